"""provenance.py: what every benchmark's JSON under bench/results/ starts with, so that a
result says where it came from: the UTC date, the commit measured (with "-dirty" when the
worktree had uncommitted changes), the load average (the machine is shared) and the cores.
Dated figures live in these files (or in git history), not in the docs."""

import os
import subprocess
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))


def commit():
    """The checkout's commit, or "unknown" outside git."""
    def git(*args):
        return subprocess.run(["git", "-C", ROOT, *args], capture_output=True, text=True).stdout.strip()
    head = git("rev-parse", "--short=12", "HEAD")
    if not head:
        return "unknown"
    return head + ("-dirty" if git("status", "--porcelain", "--untracked-files=no") else "")


def provenance():
    return {"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "commit": commit(),
            "load_average": os.getloadavg(), "cores": os.cpu_count()}
