"""The study around the pipeline: ``results/tables.md`` and the tables across results folders,
assembled from what the notebooks wrote (``report``; the writers themselves are ``greenloop.report``),
which table and figure of the papers the results hold (``coverage``), and papermill sweeps of any
notebook on Dask (``sweep``)."""
