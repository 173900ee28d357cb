"""Running work over many frames or runs: local process pools or Dask, and progress reporting.

Modules are imported on use (``from coloradar.batch.run_processing import process_run``) so
that importing the package costs nothing.
"""
