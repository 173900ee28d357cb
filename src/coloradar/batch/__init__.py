"""Running work over many frames or runs: local process pools or Dask, and progress reporting.

* :mod:`.driver` — :func:`~.driver.process` / :func:`~.driver.process_dataset`: a run or a
  whole dataset, in chunks of frames, resumable, with a JSON report; it plans and dispatches
  the work (what to do travels as one :class:`~.driver.ProcessingJob`).
* :mod:`.output_folder` — :class:`~.output_folder.ProcessedRun`, the one owner of a processed
  run's output folder: paths, manifest, valid and stale frames, lock, partial files; and
  :class:`~.output_folder.JobOutputs`, a job's folders opened (checked, locked, prepared) and
  closed (report, unlock) together.
* :mod:`.run_processing` — :func:`~.run_processing.process_run` (one run) and
  :func:`~.run_processing.process_frames` (the plain unit of work).
* :mod:`.executors` — one interface over a serial loop, a local process pool and Dask.
* :mod:`.chunks`, :mod:`.manifest`, :mod:`.report` — the worker task, what the manifest
  records (settings, calibration fingerprint, input versions; no files), the report.

Modules are imported on use (``from coloradar.batch.driver import process_dataset``) so that
importing the package costs nothing.
"""
