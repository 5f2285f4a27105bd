"""The study around the pipeline: results on disk and ``results/tables.md`` (``report``), which
table and figure of the papers the results hold (``coverage``), and papermill sweeps of any
notebook on Dask (``sweep``)."""
