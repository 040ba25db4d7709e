"""Batch pipelines: many slicerecon cases over a directory, on Dask.

* :mod:`pipelines.discover`: find the cases of an input directory and give each
  a safe, unique name (:func:`~pipelines.discover.discover_cases`).
* :mod:`pipelines.batch`: run them, one Dask task per case, with failure
  records, resume and atomic outputs (:func:`~pipelines.batch.run_batch`).

The command line is ``slicerecon batch``; see ``docs/batch.md``.
"""
