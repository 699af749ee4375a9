"""A real one-node SLURM cluster on loopback, for the workflow test: munged, slurmctld and slurmd
started from a private folder and stopped again. Needs root and Debian's slurm-wlm and munge;
`why_unavailable` installs them when missing and says why when it cannot."""
import os
import shutil
import signal
import socket
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

PROGRAMS = ("munged", "mungekey", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo", "srun")
DEFAULT_CONF = Path("/etc/slurm/slurm.conf")
RUN_CONF = Path("/run/slurm/conf/slurm.conf")


def why_unavailable() -> str | None:
    """None when this machine can host the test cluster (installing slurm-wlm and munge with apt-get
    if needed), else why not."""
    if os.geteuid() != 0:
        return "slurmd runs jobs as their user only when started as root (and apt-get install needs root too)"
    if DEFAULT_CONF.exists() or RUN_CONF.parent.exists():
        return (f"this machine has a SLURM configuration of its own ({DEFAULT_CONF} or {RUN_CONF.parent}) "
                "that the jobs' inner srun would use instead of the test cluster's")
    if all(shutil.which(p) for p in PROGRAMS):
        return None
    if not shutil.which("apt-get"):
        return "slurm-wlm and munge are not installed and there is no apt-get to install them"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "slurm-wlm", "munge"]):
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            return f"`{' '.join(cmd)}` failed: {(proc.stderr or proc.stdout).strip()[-500:]}"
    missing = [p for p in PROGRAMS if not shutil.which(p)]
    return f"after apt-get install, still missing: {', '.join(missing)}" if missing else None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def node_memory_mb() -> int:
    """MemTotal less a margin, so that slurmd's own memory check accepts the node."""
    with open("/proc/meminfo") as f:
        total_kb = int(next(line for line in f if line.startswith("MemTotal")).split()[1])
    return int(total_kb / 1024 * 0.9)


def slurm_conf(root: Path, host: str, cpus: int) -> str:
    """A minimal cluster: one node (this host on 127.0.0.1), one partition, no accounting database,
    no cgroups (proctrack/linuxproc, task/none) so it runs inside a container too."""
    return f"""\
ClusterName=physmotiontest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={free_port()}
SlurmdPort={free_port()}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={root}/munge/munge.socket
StateSaveLocation={root}/state
SlurmdSpoolDir={root}/spool
SlurmctldPidFile={root}/slurmctld.pid
SlurmdPidFile={root}/slurmd.pid
SlurmctldLogFile={root}/slurmctld.log
SlurmdLogFile={root}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/builtin
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
ReturnToService=2
MinJobAge=600
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={node_memory_mb()} State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def wait_for(check, what: str, logs: list[Path], timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.5)
    tails = "\n".join(f"--- {p.name}\n{p.read_text()[-2000:]}" for p in logs if p.exists())
    raise RuntimeError(f"{what} did not come up within {timeout_s:.0f} s\n{tails}")


@contextmanager
def slurm_cluster(root: Path):
    """Start munged, slurmctld and slurmd under `root`; yield the environment for SLURM clients
    (SLURM_CONF set); stop the three daemons afterwards, whatever happened."""
    root.mkdir(parents=True, exist_ok=True)
    for sub in ("munge", "state", "spool"):
        (root / sub).mkdir(mode=0o700, exist_ok=True)
    host = socket.gethostname().split(".")[0]
    conf = root / "slurm.conf"
    conf.write_text(slurm_conf(root, host, os.cpu_count() or 1))
    env = {**os.environ, "SLURM_CONF": str(conf)}
    key = root / "munge" / "munge.key"
    subprocess.run(["mungekey", "--create", "--keyfile", str(key)], check=True, capture_output=True)
    started: list[subprocess.Popen] = []
    made_run_dir = not RUN_CONF.parent.parent.exists()
    try:
        # The executor's job step strips SLURM_* (SLURM_CONF too) before its inner srun, which then looks
        # for /etc/slurm/slurm.conf and, as on configless clusters, /run/slurm/conf/slurm.conf: link ours there.
        RUN_CONF.parent.mkdir(parents=True)
        RUN_CONF.symlink_to(conf)
        # Foreground daemons (-F / -D), so that each is our child and we stop exactly what we started.
        started.append(subprocess.Popen(
            ["munged", "-F", "--force", f"--socket={root}/munge/munge.socket", f"--key-file={key}",
             f"--pid-file={root}/munge/munged.pid", f"--log-file={root}/munged.log",
             f"--seed-file={root}/munge/munged.seed"], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
        wait_for(lambda: (root / "munge" / "munge.socket").exists(), "munged", [root / "munged.log"])
        started.append(subprocess.Popen(["slurmctld", "-D", "-f", str(conf)], env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
        started.append(subprocess.Popen(["slurmd", "-D", "-f", str(conf)], env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))

        def node_idle() -> bool:
            proc = subprocess.run(["sinfo", "-h", "-N", "-o", "%t"], env=env, capture_output=True, text=True)
            return proc.returncode == 0 and proc.stdout.strip() == "idle"

        wait_for(node_idle, "the SLURM node", [root / "slurmctld.log", root / "slurmd.log"], timeout_s=60)
        yield env
    finally:
        for proc in reversed(started):
            proc.send_signal(signal.SIGTERM)
        for proc in reversed(started):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        RUN_CONF.unlink(missing_ok=True)
        shutil.rmtree(RUN_CONF.parent.parent if made_run_dir else RUN_CONF.parent, ignore_errors=True)
