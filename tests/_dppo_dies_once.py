"""``python -m rlcore.dppo``, except that worker 1 kills itself (SIGKILL) when it starts its third update, once.

The killed-worker test launches this under torchrun instead of polling the job from outside and killing a worker
after some time: the death happens at a fixed point of the run, whatever the machine's load. The marker file
(``RLCORE_TEST_DIE_ONCE``) makes the restarted worker live.
"""

import os
import signal
import sys
from pathlib import Path

from rlcore import dppo

MARKER = Path(os.environ["RLCORE_TEST_DIE_ONCE"])
real_update = dppo.ppo_update
updates = 0


def update_or_die(*args, **kwargs):
    global updates
    updates += 1
    if os.environ.get("RANK") == "1" and updates == 3 and not MARKER.exists():
        MARKER.write_text("worker 1 killed itself at its third update\n")
        os.kill(os.getpid(), signal.SIGKILL)
    return real_update(*args, **kwargs)


dppo.ppo_update = update_or_die
sys.exit(dppo.main())
