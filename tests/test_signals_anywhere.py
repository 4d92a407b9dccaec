"""SIGINT and SIGTERM end a run within seconds wherever it is: here in start-up work
that runs inside a critical block (the first robot is drawn and saved there) and would
take hours. The signal is held back only :data:`evo.interrupt.HOLD_S` seconds."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
from test_evolution import ENV, main_cmd

from evo.run.store import RunStore

ENDLESS_DRAW = [
    "+exp=smoke", "executor=serial", "record=off",
    # Every random robot is too big for the limits, and there are 10^8 draws to try.
    "morphology.generator.p_empty=0", "morphology.limits.max_modules=4",
    "morphology.generator.max_tries=100000000",
]


@pytest.mark.slow
def test_sigterm_ends_a_run_stuck_in_slow_start_up_work(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    proc = subprocess.Popen(main_cmd(*ENDLESS_DRAW, f"hydra.run.dir={run_dir}"), cwd=tmp_path,
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not (run_dir / "state.json").exists():  # the loop starts drawing robots
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
            time.sleep(0.05)
        time.sleep(1.0)
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)  # without the bound: hours
        print(f"ended {time.monotonic() - sent:.1f} s after SIGTERM")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143 and "Traceback" not in err, err[-3000:]
    assert err.strip().splitlines()[-1] == (
        f"interrupted; continue with: python evo/main.py resume={run_dir}")
    saved = RunStore(run_dir).load()  # what was saved is a state the run resumes from
    assert saved.next_birth == 0 and not saved.history
