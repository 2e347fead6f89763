"""scripts/warm_numba.py (run by scripts/setup.sh) compiles every kernel signature a replay of
the bundled trials uses: after it, such a replay compiles nothing."""
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

# In a fresh process: warm up, then replay the vessel trial through the graph and the offline
# path and count the kernels numba compiled for them (a signature the warm-up did not build).
CHECK = """
import runpy, sys, tempfile
from numba.core.registry import CPUDispatcher
from ins_gnss_ros.gnss import lambda_search
from ins_gnss_ros.nav import _kernels
from ins_gnss_ros.trial.offline import replay_offline
from ins_gnss_ros.trial.replay import replay

runpy.run_path("scripts/warm_numba.py", run_name="__main__")
kernels = [k for m in (_kernels, lambda_search) for k in vars(m).values()
           if isinstance(k, CPUDispatcher)]
before = {k: len(k.signatures) for k in kernels}
with tempfile.TemporaryDirectory() as tmp:
    replay("bags/vessel_waves", "config/sea_demo.yaml", tmp + "/graph")
    replay_offline("bags/vessel_waves", "config/sea_demo.yaml", tmp + "/offline")
print([(k.__name__, [str(s) for s in k.signatures[before[k]:]]) for k in kernels
       if len(k.signatures) > before[k]])
"""


def test_warm_up_covers_a_replay():
    out = subprocess.run([sys.executable, "-c", CHECK], cwd=REPO, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"
