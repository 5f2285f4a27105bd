"""The speed study and the home of streaming code: the paper's streaming loop-closure detector
(``stream``: raw frames in, closure events out), greenloop-seq's and SeqSLAM's (``seqstream``,
``seqslam_stream``, with the score matrices computed by streaming them), the one timing definition
(``timing``), and the benchmarks (``bench``, ``make bench``; ``scale``, ``make bench-scale``)."""
