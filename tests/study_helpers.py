"""Helpers shared by the study tests: a child process that SIGKILLs itself mid-study."""


def sigkill_after_rows(kill_at: int, body: str, path_arg: bool = False) -> str:
    """Python source for ``python -c``: patch :meth:`svgs_sim.studies.store.ResultStore.append` to
    SIGKILL the process right after the store has fsynced a task's rows and holds ``kill_at``
    or more (the kill lands at a known point: no polling, no timing window), then run ``body``.
    ``path_arg``: put ``sys.argv[1]`` on ``sys.path`` first (to import a test module)."""
    return "\n".join([
        "import os, signal, sys",
        *(["sys.path.insert(0, sys.argv[1])"] if path_arg else []),
        "from svgs_sim.studies.store import ResultStore",
        "_append = ResultStore.append",
        "def append(self, rows):",
        "    n = _append(self, rows)",
        f"    if len(self.done_ids) >= {int(kill_at)}:",
        "        os.kill(os.getpid(), signal.SIGKILL)",
        "    return n",
        "ResultStore.append = append",
        body.strip(),
        "",
    ])
