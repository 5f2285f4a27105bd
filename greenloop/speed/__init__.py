"""Measuring only, above ``methods`` (whose streaming detectors it times, never defines): the one
timing definition, decoded frame -> decision, for every method alike (``timing``; its clock is
``greenloop.util.clock``), the speed benchmark of notebook 06 and ``make bench`` (``bench``), the
scaling benchmark of ``make bench-scale`` (``scale``) and the long-stream measurement of a
``detect`` run on a long recording (``long_stream``). A user's ``detect`` never runs through here."""
