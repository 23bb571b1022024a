"""Fixtures: a real tpr-extractor and tpr-indexer on loopback, started from
the build folder (TPR_BINARY_DIR) with --listen 127.0.0.1:0; the port is
read from the "(port N)" line each server logs."""

import os
import re
import shutil
import subprocess
import tempfile
import time

import pytest

BINARY_DIR = os.environ.get("TPR_BINARY_DIR", os.path.join(os.path.dirname(__file__), "../../build"))


def binary(name):
    """Where the build put executable `name` (the build folder, or the
    folder of its target)."""
    for sub in ("", "extractor", "indexer", "client", "web"):
        candidate = os.path.join(BINARY_DIR, sub, name)
        if os.access(candidate, os.X_OK):
            return candidate
    return os.path.join(BINARY_DIR, name)


class Server:
    def __init__(self, name, args, log):
        self.log = log
        with open(log, "w") as out:
            self.process = subprocess.Popen(
                [binary(name), "--listen", "127.0.0.1:0", *args],
                stdout=out, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            m = re.search(r"\(port (\d+)\)", open(log).read())
            if m:
                self.address = f"127.0.0.1:{m.group(1)}"
                return
            if self.process.poll() is not None:
                raise RuntimeError(f"{name} exited: {open(log).read()}")
            time.sleep(0.02)
        raise RuntimeError(f"{name} did not report its port")

    def stop(self):
        self.process.terminate()
        self.process.wait(30)


@pytest.fixture
def services():
    work = tempfile.mkdtemp(prefix="tpr-python-")
    extractor = Server("tpr-extractor", ["--threads", "2"], os.path.join(work, "extractor.log"))
    indexer = Server("tpr-indexer", ["--data-dir", os.path.join(work, "data")],
                     os.path.join(work, "indexer.log"))
    try:
        yield extractor, indexer, work
    finally:
        extractor.stop()
        indexer.stop()
        shutil.rmtree(work, ignore_errors=True)


@pytest.fixture
def meshes(services):
    """A folder `set/` of 2 classes x 2 poses made by tpr-synth."""
    work = services[2]
    folder = os.path.join(work, "set")
    subprocess.run([binary("tpr-synth"), "--out", folder, "--classes", "2",
                    "--poses", "2", "--vertices", "800"], check=True, capture_output=True)
    return folder
