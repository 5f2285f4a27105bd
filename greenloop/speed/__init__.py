"""The speed study: the streaming loop-closure detector (``stream``: raw frames in, closure
events out) and the benchmark that times it against the paper's pipeline (``bench``, ``make bench``)."""
