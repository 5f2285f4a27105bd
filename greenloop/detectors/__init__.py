"""Loop-closure detectors behind one interface, and the one registry of them.

``interface`` defines what a detector provides (an :class:`~greenloop.detectors.interface.Entry`,
a record of functions) and what it is given (:class:`~greenloop.detectors.interface.Data`, the
described frames of one dataset and its split). One module per family:

    single_frame   cosine of one frame's descriptor (CNNs, SIFT-BoVW, pixels) to every stored frame
    greenloop_seq  greenloop-seq, greenloop-seq-fast and the named default (``seqmatch``)
    seqslam        SeqSLAM at OpenSeqSLAM's parameters and tuned on the same grid (``greenloop.seqslam``)
    dictionary     the main paper's CNN + frequency dictionary (decisions only, no score)

``registry.REGISTRY`` ({name: Entry}) is what notebook 13's leaderboard
(``greenloop.experiments.leaderboard``), ``python -m greenloop detect --method NAME`` and the tests
read: a new detector is one module and one line there (docs/ARCHITECTURE.md, "Adding a detector").
"""
