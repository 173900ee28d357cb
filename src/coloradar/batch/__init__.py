"""Running work over many frames or runs: local process pools or Dask, and progress reporting.

* :mod:`.driver` — :func:`~.driver.process` / :func:`~.driver.process_dataset`: a run or a
  whole dataset, in chunks of frames, resumable, with a JSON report.
* :mod:`.run_processing` — :func:`~.run_processing.process_run` (one run) and
  :func:`~.run_processing.process_frames` (the plain unit of work).
* :mod:`.executors` — one interface over a serial loop, a local process pool and Dask.
* :mod:`.chunks`, :mod:`.layout`, :mod:`.manifest`, :mod:`.report`, :mod:`.progress` — the
  worker task, the output layout and its completeness rules, the settings manifest and lock,
  the report, the progress line.

Modules are imported on use (``from coloradar.batch.driver import process_dataset``) so that
importing the package costs nothing.
"""
