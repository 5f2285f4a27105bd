"""Building blocks every stage shares, importing nothing else of greenloop: integer-argument
checks (``checks``), atomic file writes (``files``), the on-disk model and descriptor cache
(``cache``), terminal progress bars (``progress``), the early-stopping rule (``stopping``), TensorFlow's devices where no GPU is
(``devices``), thread limits (``threads``), the one wall clock (``clock``) and the compiled CPU kernels
(``numba_kernels``)."""
