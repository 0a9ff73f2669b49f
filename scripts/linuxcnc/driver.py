#!/usr/bin/python3
"""Drives a running headless LinuxCNC through its ``linuxcnc`` Python module.

Runs under Debian's /usr/bin/python3 (the interpreter the linuxcnc module is
built for) as the simulator's user; fivecal's own interpreter talks to it
through two JSON files only:

    driver.py JOB.json OUT.json

JOB: {"setup": ["M428", ...],                     MDI lines after homing
      "moves": ["G1 X.. Y.. Z.. A.. C.. F..", ...],  one MDI line per pose
      "hal_pins": ["joint.0.motor-pos-cmd", ...],   read after each move
      "settle": seconds to wait after each move before reading,
      "program": "file.ngc" (run in AUTO mode after the moves),
      "program_timeout": seconds,
      "trace": true to record [motion line, commanded joints...] every 50 ms of the program,
      "timeout": seconds per command}

A simulated probe (fivecal.io.linuxcnc.probe_sim_hal) needs nothing from
this driver: the program loads its plane with M67 and arms it with M62.
OUT: {"joints": [[j0..j4], ...] (commanded joint positions after each move),
      "joints_actual": [...], "position": [...] (world, after each move),
      "hal": [[pin values], ...] (after each move), "hal_start": [pin values after homing],
      "kinematics_type": ..., "errors": [...]}

Every wait has a timeout, so a stuck controller fails the job instead of
hanging the caller.
"""
import json
import os
import sys
import time

import hal
import linuxcnc


def wait_for(pred, s, timeout, what):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        s.poll()
        if pred():
            return
        time.sleep(0.02)
    raise TimeoutError(f"LinuxCNC: timed out after {timeout} s waiting for {what}")


def main(job_path, out_path):
    with open(job_path) as f:
        job = json.load(f)
    timeout = float(job.get("timeout", 30.0))
    s = linuxcnc.stat()
    c = linuxcnc.command()
    e = linuxcnc.error_channel()
    errors = []

    def check_errors():
        while True:
            err = e.poll()
            if not err:
                return
            kind, text = err
            if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
                errors.append(text)

    # The controller may still be starting: poll until task answers.
    t0 = time.monotonic()
    while True:
        try:
            s.poll()
            break
        except Exception:  # linuxcnc.error, or SystemError before task is up
            if time.monotonic() - t0 > timeout:
                raise TimeoutError("LinuxCNC: no status channel")
            time.sleep(0.2)

    c.state(linuxcnc.STATE_ESTOP_RESET)
    c.state(linuxcnc.STATE_ON)
    wait_for(lambda: s.task_state == linuxcnc.STATE_ON, s, timeout, "machine on")
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete(timeout)
    c.teleop_enable(0)
    c.wait_complete(timeout)
    c.home(-1)
    c.wait_complete(timeout)
    njoints = s.joints
    wait_for(lambda: all(s.homed[:njoints]), s, timeout, "homing")

    def at_rest():
        # Idle and in position can both hold for a moment before a queued move
        # starts (seen on a loaded machine: joints read 0.3 mm short of the
        # move's end). At rest = also an empty planner queue and commanded
        # joints that stay put over a few servo periods.
        if not (s.interp_state == linuxcnc.INTERP_IDLE and s.inpos and s.queue == 0):
            return False
        before = list(s.joint_position[:njoints])
        time.sleep(0.02)
        s.poll()
        return (s.interp_state == linuxcnc.INTERP_IDLE and s.inpos and s.queue == 0
                and list(s.joint_position[:njoints]) == before)

    def mdi(line):
        c.mode(linuxcnc.MODE_MDI)
        c.wait_complete(timeout)
        c.mdi(line)
        if c.wait_complete(timeout) == -1:
            raise TimeoutError(f"LinuxCNC: MDI '{line}' did not complete in {timeout} s")
        wait_for(at_rest, s, timeout, f"MDI '{line}' to finish")
        check_errors()
        if errors:
            raise RuntimeError(f"LinuxCNC refused '{line}': {errors[-1]}")

    pins = job.get("hal_pins", [])
    if pins:
        # hal.get_value needs a component of this process in HAL
        comp = hal.component(f"fivecal-driver-{os.getpid()}")
        comp.ready()
    settle = float(job.get("settle", 0.0))
    out = {"joints": [], "joints_actual": [], "position": [], "probed": [], "hal": [], "trace": [],
           "hal_start": [hal.get_value(p) for p in pins]}
    for line in job.get("setup", []):
        mdi(line)
    for line in job.get("moves", []):
        mdi(line)
        if settle:
            time.sleep(settle)
        s.poll()
        out["hal"].append([hal.get_value(p) for p in pins])
        out["joints"].append(list(s.joint_position[:njoints]))
        out["joints_actual"].append(list(s.joint_actual_position[:njoints]))
        out["position"].append(list(s.position[:9]))
        out["probed"].append(list(s.probed_position[:9]))
    if job.get("program"):
        ptimeout = float(job.get("program_timeout", 600))
        c.mode(linuxcnc.MODE_AUTO)
        c.wait_complete(timeout)
        c.program_open(os.path.abspath(job["program"]))
        c.wait_complete(timeout)
        c.auto(linuxcnc.AUTO_RUN, 0)
        t0 = time.monotonic()
        started = False
        while True:
            s.poll()
            check_errors()
            if errors:
                where = [round(v, 4) for v in s.joint_actual_position[:5]]
                raise RuntimeError(f"LinuxCNC stopped the program at line {s.motion_line} "
                                   f"(interpreter at {s.current_line}, joints {where}): {errors[-1]}")
            if s.interp_state != linuxcnc.INTERP_IDLE:
                started = True
                if job.get("trace"):
                    out["trace"].append([s.motion_line] + list(s.joint_position[:njoints]))
            elif started or time.monotonic() - t0 > 30:
                # a loaded machine may take seconds to start the program: the
                # driver must not read the log of a program still to come
                break
            if time.monotonic() - t0 > ptimeout:
                c.abort()
                raise TimeoutError(f"LinuxCNC: program did not finish in {ptimeout} s")
            time.sleep(0.05)
    s.poll()
    out["kinematics_type"] = s.kinematics_type
    out["errors"] = errors
    with open(out_path, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
