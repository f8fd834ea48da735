"""results.py: the PASS/FAIL/SKIP lines the Python test scripts print for tests/run.sh.

    results = Results("http")
    results.check("name", fn)   # fn passes, fails (an exception, with its message) or skips
    results.report("name", ok, why)
    sys.exit(1 if results.failures else 0)
"""


class Skip(Exception):
    """Raised by a test that cannot run here; it says why."""


class Results:
    def __init__(self, label):
        self.label = label
        self.failures = 0

    def report(self, name, ok, why=""):
        if ok:
            print(f"PASS {self.label}.{name}", flush=True)
        else:
            self.failures += 1
            print(f"FAIL {self.label}.{name}: {why}", flush=True)

    def check(self, name, fn):
        """Runs one test; an exception is a failure with its message, never a crash of the suite."""
        try:
            fn()
        except Skip as e:
            print(f"SKIP {self.label}.{name}: {e}", flush=True)
        except AssertionError as e:
            self.report(name, False, str(e) or "assertion failed")
        except Exception as e:  # noqa: BLE001 - any error is this test's failure
            self.report(name, False, f"{type(e).__name__}: {e}")
        else:
            self.report(name, True)
