"""Starts and stops fivecal's headless LinuxCNC simulators (scripts/linuxcnc/sim)
and runs jobs in them through scripts/linuxcnc/driver.py.

LinuxCNC's realtime layer refuses to run as root, so as root the simulator runs
as the unprivileged user scripts/linuxcnc_setup.sh creates (fivecal-cnc); as
any other user it runs as that user. Every wait has a timeout and the
simulator is always stopped (``with Sim(...) as sim``), so a broken controller
fails a test instead of hanging it. Only one LinuxCNC can run on a machine at a
time (fixed shared-memory keys, port 5007): a file lock serialises sessions.
"""
from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from typing import Dict, Iterable, List, Optional

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SIM_DIR = os.path.join(ROOT, "scripts", "linuxcnc", "sim")
DRIVER = os.path.join(ROOT, "scripts", "linuxcnc", "driver.py")
SETUP = os.path.join(ROOT, "scripts", "linuxcnc_setup.sh")
CNC_USER = os.environ.get("FIVECAL_CNC_USER", "fivecal-cnc")
SYSTEM_PYTHON = "/usr/bin/python3"  # the interpreter Debian's linuxcnc module is built for
LOCK = os.path.join(tempfile.gettempdir(), "fivecal-linuxcnc.lock")


def unavailable_reason() -> Optional[str]:
    """Why the simulator cannot run here, or None when it can."""
    if shutil.which("linuxcnc") is None:
        return "LinuxCNC is not installed (bash scripts/linuxcnc_setup.sh installs linuxcnc-uspace)"
    if not os.path.exists(SYSTEM_PYTHON):
        return f"{SYSTEM_PYTHON} (the interpreter of LinuxCNC's Python module) is missing"
    return None


def _as_user(cmd: List[str]) -> List[str]:
    if os.geteuid() != 0:
        return cmd
    return ["runuser", "-u", CNC_USER, "--"] + cmd


def _ensure_user():
    if os.geteuid() != 0:
        return
    if subprocess.run(["id", CNC_USER], capture_output=True).returncode != 0:
        subprocess.run(["bash", SETUP], check=True, timeout=900)


def _stat(pid: int):
    """(ppid, session id) of a process, or None once it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            rest = f.read().rsplit(")", 1)[1].split()
        return int(rest[1]), int(rest[3])
    except (OSError, IndexError, ValueError):
        return None


def _session(sid: int) -> List[int]:
    """Processes of session sid (the simulator's, started with a new session)."""
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = _stat(int(name))
            if st and st[1] == sid:
                out.append(int(name))
    return out


def _comm(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return ""


class Sim:
    """A headless LinuxCNC session of ``kins`` ('xyzac-trt', 'xyzbc-trt' or '5axiskins').

    hal: the text of fivecal-kins.hal (the pins fivecal exports);
    joint_ini: extra INI lines per joint number (e.g. COMP_FILE);
    files: extra files written next to the INI (name -> text).
    """

    def __init__(self, kins: str, hal: str = "", joint_ini: Optional[Dict[int, Iterable[str]]] = None,
                 files: Optional[Dict[str, str]] = None, timeout: float = 60.0):
        if kins not in ("xyzac-trt", "xyzbc-trt", "5axiskins"):
            raise ValueError(f"kins: expected 'xyzac-trt', 'xyzbc-trt' or '5axiskins', got {kins!r}")
        self.kins, self.hal, self.timeout = kins, hal, timeout
        self.joint_ini = joint_ini or {}
        self.files = files or {}
        self.dir: Optional[str] = None
        self.proc: Optional[subprocess.Popen] = None
        self._lock = None

    # ---- lifecycle ----------------------------------------------------
    def __enter__(self) -> "Sim":
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()

    def start(self):
        reason = unavailable_reason()
        if reason:
            raise RuntimeError(reason)
        _ensure_user()
        self._lock = open(LOCK, "a")
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        self.dir = tempfile.mkdtemp(prefix=f"fivecal-{self.kins}-")
        shutil.copytree(SIM_DIR, self.dir, dirs_exist_ok=True)
        # the simulator user may not be able to read the checkout (/root/...)
        shutil.copy(DRIVER, os.path.join(self.dir, "driver.py"))
        ini_path = os.path.join(self.dir, f"{self.kins}.ini")
        with open(ini_path) as f:
            ini = f.read()
        for j, lines in self.joint_ini.items():
            head = f"[JOINT_{j}]\n"
            if head not in ini:
                raise ValueError(f"joint_ini: no [JOINT_{j}] in {self.kins}.ini")
            ini = ini.replace(head, head + "".join(l + "\n" for l in lines))
        with open(ini_path, "w") as f:
            f.write(ini)
        with open(os.path.join(self.dir, "fivecal-kins.hal"), "w") as f:
            f.write(self.hal)
        for name, text in self.files.items():
            with open(os.path.join(self.dir, name), "w") as f:
                f.write(text)
        if os.geteuid() == 0:
            subprocess.run(["chown", "-R", CNC_USER, self.dir], check=True)
        self.log = open(os.path.join(self.dir, "linuxcnc.log"), "w")
        self.proc = subprocess.Popen(_as_user(["linuxcnc", ini_path]), cwd=self.dir,
                                     stdout=self.log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        # The display program starts last, once HAL, motion and task are up.
        t0 = time.monotonic()
        while self._display() is None:
            if self.proc.poll() is not None:
                raise RuntimeError(f"LinuxCNC exited while starting:\n{self.log_text()}")
            if time.monotonic() - t0 > self.timeout:
                raise TimeoutError(f"LinuxCNC did not start in {self.timeout} s:\n{self.log_text()}")
            time.sleep(0.2)

    def _display(self) -> Optional[int]:
        for pid in _session(self.proc.pid):
            if _comm(pid) == "linuxcncrsh":
                return pid
        return None

    def log_text(self) -> str:
        try:
            with open(os.path.join(self.dir, "linuxcnc.log")) as f:
                return f.read()[-4000:]
        except (OSError, TypeError):
            return ""

    def stop(self):
        """Stops LinuxCNC the way its own script does on exit: the display
        program (linuxcncrsh) ends and the script's cleanup unloads realtime."""
        try:
            if self.proc is not None and self.proc.poll() is None:
                display = self._display()
                if display is not None:
                    self._signal(display, signal.SIGTERM)
                try:
                    self.proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    pass
            if self.proc is not None:
                # Last resort: whatever of the session survived (a start that
                # never got as far as the display), then realtime itself.
                left = [p for p in _session(self.proc.pid) if p != os.getpid()]
                for pid in left:
                    self._signal(pid, signal.SIGKILL)
                if self.proc.poll() is None:
                    self.proc.wait(timeout=10)
                if left:
                    subprocess.run(_as_user(["halrun", "-U"]), capture_output=True, timeout=30,
                                   cwd=self.dir or "/")
        finally:
            self.proc = None
            if getattr(self, "log", None):
                self.log.close()
            if self.dir and not os.environ.get("FIVECAL_KEEP_SIM"):
                shutil.rmtree(self.dir, ignore_errors=True)
            if self._lock is not None:
                fcntl.flock(self._lock, fcntl.LOCK_UN)
                self._lock.close()
                self._lock = None

    def _signal(self, pid, sig):
        # The processes belong to the simulator user; root may signal them.
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass

    # ---- jobs ---------------------------------------------------------
    def run(self, moves: List[str], setup: Iterable[str] = ("M428",), timeout: float = 30.0,
            total_timeout: Optional[float] = None, hal_pins: Iterable[str] = (),
            settle: float = 0.0, program: Optional[str] = None,
            program_timeout: float = 600.0, trace: bool = False) -> dict:
        """Homes, runs the setup MDI lines, then each move; returns the driver's
        output (joints after each move, world position, kinematics type)."""
        if self.proc is None or self.proc.poll() is not None:
            raise RuntimeError(f"LinuxCNC is not running:\n{self.log_text()}")
        job = os.path.join(self.dir, "job.json")
        out = os.path.join(self.dir, "out.json")
        with open(job, "w") as f:
            json.dump({"setup": list(setup), "moves": list(moves), "timeout": timeout,
                       "hal_pins": list(hal_pins), "settle": settle, "program": program,
                       "program_timeout": program_timeout, "trace": trace}, f)
        if os.path.exists(out):
            os.remove(out)
        if os.geteuid() == 0:
            subprocess.run(["chown", CNC_USER, job], check=True)
        limit = total_timeout or (60.0 + (timeout + settle) * (len(moves) + 10)
                                  + (program_timeout + 10 if program else 0))
        r = subprocess.run(_as_user([SYSTEM_PYTHON, os.path.join(self.dir, "driver.py"), job, out]),
                           cwd=self.dir,
                           capture_output=True, text=True, timeout=limit)
        if r.returncode != 0:
            raise RuntimeError(f"LinuxCNC driver failed ({r.returncode}):\n{r.stderr[-3000:]}\n"
                               f"--- linuxcnc log ---\n{self.log_text()}")
        with open(out) as f:
            return json.load(f)

    def read(self, name: str) -> str:
        """A file the controller wrote in its configuration folder (a probe log)."""
        with open(os.path.join(self.dir, name)) as f:
            return f.read()
