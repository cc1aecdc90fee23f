"""Batch planning: many requests (plan requests and contour requests, G-code programs) on a
local process pool or a Dask cluster.

* :mod:`.engine`: :func:`plan_item`, the one function that plans one request wherever it
  runs (as the service's typed job, under its bounds: :func:`app.executors.run_bounded`) and
  returns a compact outcome (where it ran included); :class:`~.engine.BatchChunkJob`, a chunk
  of items as one typed job; workers warm up once.
* :mod:`.base`, :mod:`.executors`, :mod:`.cluster`: the engines, each one of the service's
  executors (:class:`app.executors.JobExecutor`: in-process, a local
  :class:`app.workers.PlanPool`, :class:`app.cluster.DaskExecutor`).
* :mod:`.runner`: the dispatcher (bounded, chunked, submits through ``JobExecutor.submit``,
  retries the items of a lost worker).
* :mod:`.inputs`, :mod:`.summary`, :mod:`.progress`, :mod:`.cli`: ``rangeplan batch``.
* :mod:`.store`, :mod:`.service`, :mod:`.api`: ``/v1/batches`` in the HTTP service.

This package never imports the editor; the engine modules import no web framework.
"""
