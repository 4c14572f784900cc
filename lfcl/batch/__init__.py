"""`lfcl batch`: many captures through the pipeline on Dask, resumable."""
