"""greenloop-seq, this study's detector: its stages (seqmatch), its streaming detector (seqstream),
candidate mode for long recordings (candidates) and its registry entries (entry)."""
