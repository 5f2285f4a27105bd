"""SeqSLAM (Milford & Wyeth 2012) at OpenSeqSLAM's parameters: its stages, its streaming detector
and its registry entry."""
