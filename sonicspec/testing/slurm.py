"""A real single-node SLURM cluster for tests: munge, slurmctld and slurmd on this machine.

Uses Debian's ``slurm-wlm`` and ``munge``. Needs root (the daemons run as root here) and writes
``/etc/slurm/slurm.conf``, because job steps (``srun`` inside a batch job) look for the
configuration there; an existing file not written by this module is never touched, and the
cluster is skipped instead. Accounting is disabled, so clients must use ``squeue`` for job
status and submit without an account.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

CONF = Path("/etc/slurm/slurm.conf")
MARKER = "# written by sonicspec.testing.slurm"
DAEMONS = ("munged", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo", "srun")


class SlurmUnavailable(RuntimeError):
    """This machine cannot run the test cluster (the reason says why)."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _config(work: Path, cpus: int, mem_mb: int) -> str:
    host = socket.gethostname()
    return f"""{MARKER}
ClusterName=sonicspec-test
SlurmctldHost={host}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={work}/munge.socket
CredType=cred/munge
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
StateSaveLocation={work}/state
SlurmdSpoolDir={work}/spool
SlurmctldPidFile={work}/slurmctld.pid
SlurmdPidFile={work}/slurmd.pid
SlurmctldLogFile={work}/slurmctld.log
SlurmdLogFile={work}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
NodeName={host} CPUs={cpus} RealMemory={mem_mb} State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
"""


def _pid(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (FileNotFoundError, ValueError):
        return None


@contextmanager
def single_node_slurm(work: Path, *, cpus: int | None = None,
                      mem_mb: int = 8000, start_timeout_s: float = 30.0) -> Iterator[Path]:
    """Start munge + slurmctld + slurmd with state under ``work``; yield the config path."""
    if os.geteuid() != 0:
        raise SlurmUnavailable("the test cluster's daemons need root")
    missing = [d for d in DAEMONS if shutil.which(d) is None and
               not Path(f"/usr/sbin/{d}").exists()]
    if missing:
        raise SlurmUnavailable(f"missing {', '.join(missing)}: apt-get install slurm-wlm munge")
    if CONF.exists() and MARKER not in CONF.read_text():
        raise SlurmUnavailable(f"{CONF} belongs to a real cluster; not touching it")
    work.mkdir(parents=True, exist_ok=True)
    for sub in ("state", "spool"):
        (work / sub).mkdir(exist_ok=True)
    key = work / "munge.key"
    key.write_bytes(os.urandom(1024))
    key.chmod(0o400)
    CONF.parent.mkdir(parents=True, exist_ok=True)
    CONF.write_text(_config(work, cpus or os.cpu_count() or 1, mem_mb))
    env = dict(os.environ, SLURM_CONF=str(CONF))
    started: list[Path] = []
    try:
        subprocess.run(["munged", f"--key-file={key}", f"--socket={work}/munge.socket",
                        f"--pid-file={work}/munged.pid", f"--log-file={work}/munged.log",
                        f"--seed-file={work}/munge.seed", "--force"], check=True, env=env,
                       capture_output=True)
        started.append(work / "munged.pid")
        subprocess.run(["slurmctld", "-c"], check=True, env=env, capture_output=True)
        started.append(work / "slurmctld.pid")
        subprocess.run(["slurmd"], check=True, env=env, capture_output=True)
        started.append(work / "slurmd.pid")
        deadline = time.monotonic() + start_timeout_s
        while True:
            out = subprocess.run(["sinfo", "-h", "-o", "%t"], env=env, capture_output=True,
                                 text=True)
            if out.returncode == 0 and out.stdout.strip() in ("idle", "mix", "alloc"):
                break
            if time.monotonic() > deadline:
                log = (work / "slurmctld.log").read_text(errors="replace")[-2000:]
                raise SlurmUnavailable(f"the node did not become idle: {out.stdout!r}\n{log}")
            time.sleep(0.5)
        yield CONF
    finally:
        subprocess.run(["scancel", "--full", "-u", "root"], env=env, capture_output=True)
        pids = [p for p in (_pid(f) for f in reversed(started)) if p is not None]
        for pid in pids:
            try:
                os.kill(pid, 15)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + 15.0
        while pids and time.monotonic() < deadline:
            pids = [p for p in pids if Path(f"/proc/{p}").exists()]
            time.sleep(0.2)
        if CONF.exists() and MARKER in CONF.read_text():
            CONF.unlink()
