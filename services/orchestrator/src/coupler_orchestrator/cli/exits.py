"""Exit codes of the ``coupler`` command.

0 the run completed (or a participant ended it early: ``terminated``; or Ctrl-C stopped a
fleet's services after its run completed), 1 any problem (bad input, a participant failing:
``failed``), 2 a wrong command line (``coupler new``: also a NAME it cannot use or a folder
that exists), 130 interrupted (Ctrl-C or SIGTERM during a run: ``aborted``, the rows so far
kept), 128 + N the process running the run was killed by signal N
(139: SIGSEGV, a crash in an FMU running in-process; summary.json ``crashed``; ``supervisor``).
"""

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
