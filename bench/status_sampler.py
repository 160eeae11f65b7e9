#!/usr/bin/env python3
"""Reads a running previsd's status from its control socket (DESIGN.md §3: one command line in,
one JSON line out), for the live benches. One process asks for every sample: a `previs ctl` per
sample loads its 160-odd libraries each time, about 0.24 CPU-s, a quarter of a core taken from
the box being measured.

usage: status_sampler.py SOCKET PID WARMUP SECONDS OUT [--busy-after N BUSYFILE]
Waits until previsd has shown a frame (the dial times its settings at start; about 600 s at most,
less if process PID stops: exit 1), sleeps WARMUP seconds, then writes SECONDS + 1 lines to OUT, one a
second: "<unix time> <status JSON>". With --busy-after it busy-loops one core from sample N to the
end (another process loading the box) and writes when that began to BUSYFILE.
"""
import json
import os
import socket
import subprocess
import sys
import time


def status(path):
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(10)
        s.connect(path)
        s.sendall(b"status\n")
        reply = b""
        while not reply.endswith(b"\n") and (chunk := s.recv(65536)):
            reply += chunk
    return reply.decode().strip()


def alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


def wait_for_first_frame(path, pid):
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        try:
            if json.loads(status(path))["framesShown"] > 0:
                return True
        except (OSError, ValueError, KeyError):  # not listening yet, or starting
            pass
        if not alive(pid):
            return False
        time.sleep(1)
    return False


def main(argv):
    path, pid, warmup, seconds, out = argv[1], int(argv[2]), float(argv[3]), int(argv[4]), argv[5]
    busy_after, busy_file = -1, None
    if len(argv) > 6:
        if argv[6] != "--busy-after" or len(argv) != 9:
            sys.exit("status_sampler.py: usage: see its header")
        busy_after, busy_file = int(argv[7]), argv[8]
    if not wait_for_first_frame(path, pid):
        return 1
    time.sleep(warmup)
    busy = None
    try:
        with open(out, "w") as samples:
            for i in range(seconds + 1):
                if i == busy_after:
                    with open(busy_file, "w") as f:
                        f.write(f"{time.time()}\n")
                    busy = subprocess.Popen(["bash", "-c", "while :; do :; done"])
                try:
                    samples.write(f"{time.time()} {status(path)}\n")
                except (OSError, ValueError):
                    pass  # previsd gone or cut off mid-reply: the samples so far stand
                time.sleep(1)
    finally:
        if busy:
            busy.kill()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
