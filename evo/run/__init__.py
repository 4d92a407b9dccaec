"""Everything a run directory is, in one place.

* :mod:`evo.run.layout`: the name of every file and folder of a run (``RunLayout``, and
  ``TrainLayout`` for a one-robot training);
* :mod:`evo.run.files`: atomic writes and the lock that makes one process own a run;
* :mod:`evo.run.records`: the typed records of its files (``HistoryRow``, ``RunSummary``,
  ``TrainSummary``, and the robots in flight and population members that ``state.json``
  holds, ``Candidate`` and ``Member``), each with its one writer and its one reader;
* :mod:`evo.run.store`: the resumable state, saved, loaded and checked (``RunStore``).

Nothing is imported here, so that a module takes only the part it asks for. The run
directory sits below the evaluation and above the task and the robots (the layers of
``pyproject.toml``'s ``[tool.importlinter]``).
"""
