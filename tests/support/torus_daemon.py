"""One isoserve daemon over a catalog in a temporary directory (tmp/catalog.json), with
its cache dir tmp/cache, for the tests that restart it between steps (the chain files and
the chains' registry). Started at construction (ready when /healthz says 200), stopped by
its PID with SIGTERM once the partial chains are completed; stop() asserts exit 0 and
returns the log."""

import json
import os
import signal
import subprocess
import time

from client import request
from ports import free_port

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.path.abspath(os.environ.get("ISOSERVE_BIN", os.path.join(ROOT, "build/isoserve")))


class Daemon:
    def __init__(self, tmp, *extra):
        self.tmp, self.port = tmp, free_port()
        self.log_path = os.path.join(tmp, "serve.log")
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen([BIN, "serve", "--catalog", os.path.join(tmp, "catalog.json"),
                                          "--listen", f"127.0.0.1:{self.port}",
                                          "--cache-dir", os.path.join(tmp, "cache"), "--threads", "2", *extra],
                                         stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
        deadline = time.time() + 60
        while time.time() < deadline:
            try:
                if request(self.port, "/healthz", timeout=5).status == 200:
                    return
            except OSError:
                pass
            time.sleep(0.1)
        raise AssertionError("the daemon did not start")

    def settle(self, timeout=120):
        """Waits until no partial chain is left in memory: the background thread has
        completed and written the chains requests built only down to their level (a stop
        drops the completions still queued)."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            r = request(self.port, "/v1/status", timeout=5)
            if r.status != 200 or json.loads(r.body)["chains"]["partial"] == 0:
                return
            time.sleep(0.05)
        raise AssertionError("partial chains were not completed")

    def stop(self):
        self.settle()
        self.proc.send_signal(signal.SIGTERM)
        rc = self.proc.wait(timeout=60)
        with open(self.log_path) as f:
            log = f.read()
        assert rc == 0, f"exit {rc}: {log[-500:]}"
        return log
