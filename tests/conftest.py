"""Suite-wide set-up: the DEM kernels compiled (or loaded) once before pytest-xdist starts its
test processes. Otherwise, on a fresh clone, each of them compiles the same kernels at the
same time as the others (about a minute of every core), and so does every command a test
starts before the cache is filled."""

import subprocess
import sys


def pytest_configure(config):
    if hasattr(config, "workerinput"):
        return          # a test process: the controller has readied the kernels
    if not getattr(config.option, "numprocesses", None):
        return          # one process (-n0): it compiles what its tests need as they go
    done = subprocess.run([sys.executable, "-c", "from demcal.cli import main; raise SystemExit(main(['compile']))"],
                          capture_output=True, text=True)
    if done.returncode != 0:     # the tests that run the DEM will fail and say why; say it here too
        sys.stderr.write(f"demcal compile failed before the tests started:\n{done.stderr[-2000:]}\n")
