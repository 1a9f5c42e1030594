"""Past one machine: Dask as the engine of the embarrassingly parallel stages (``--scheduler``, docs/contracts.md §2).

``engine``: the ``--scheduler local:N | tcp://HOST:PORT | slurm[:JOBS]`` option, the Dask client it opens,
and ``Job`` (tasks submitted with bounded retries, one progress bar, failures reported by task); ``bench``:
the ``ci`` dataset on ``local:2`` against one process.  The stages cut their work into the pieces their
single-process and ``--shard`` paths already write (``training.sim.lut``, ``training.data.build``,
``training.fit.dataset``, ``training.validate.run``), so a cluster run writes the same files, resumes
the same way and gives the same numbers.
"""
