#!/usr/bin/python3
"""The independent ends of bench/network_live.sh (standard library only).

  network_live.py receive PORTFILE LOG    binds two UDP ports on 127.0.0.1 (FreeD, OpenTrackIO),
                                          writes "FREED_PORT OTIO_PORT" to PORTFILE, then logs
                                          one line per datagram to LOG until killed:
                                          "f RECV_S OK" (FreeD: 29 bytes, type 0xD1, checksum
                                          (0x40 - sum of bytes 0..27) mod 256) or
                                          "o RECV_S OK DELAY_MS SEQ" (OpenTrackIO: OTrk header
                                          and Fletcher-16 checked, segments reassembled;
                                          DELAY_MS = receipt (time.time()) - the sample's
                                          timing.sampleTimestamp, SEQ its
                                          timing.sequenceNumber).
  network_live.py viewer URL LOG          reads an MJPEG stream and logs the receipt time of each
                                          part ("--previsframe" boundary) until killed.
  network_live.py freeport                prints a free TCP port on 127.0.0.1.
  network_live.py analyse DIR             the report: DIR holds the run's samples, cases and logs.
"""

import json
import os
import select
import socket
import statistics
import sys
import time


def fletcher16(data):
    s1 = s2 = 0
    for b in data:
        s1 = (s1 + b) & 0xFF
        s2 = (s2 + s1) & 0xFF
    return (s2 << 8) | s1


def receive(portfile, logpath):
    freed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    otio = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for s in (freed, otio):
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind(("127.0.0.1", 0))
    with open(portfile + ".tmp", "w") as f:
        f.write(f"{freed.getsockname()[1]} {otio.getsockname()[1]}\n")
    os.rename(portfile + ".tmp", portfile)
    log = open(logpath, "w", buffering=1)
    assembling = bytearray()
    while True:
        ready, _, _ = select.select([freed, otio], [], [])
        for s in ready:
            data = s.recv(65536)
            now = time.time()
            if s is freed:
                ok = (len(data) == 29 and data[0] == 0xD1
                      and data[28] == (0x40 - sum(data[:28])) & 0xFF)
                log.write(f"f {now:.6f} {int(ok)}\n")
                continue
            # OpenTrackIO: 16-byte header, big-endian (docs/opentrackio.md).
            ok = (len(data) >= 16 and data[:4] == b"OTrk")
            if ok:
                offset = int.from_bytes(data[8:12], "big")
                flag_len = int.from_bytes(data[12:14], "big")
                last, length = bool(flag_len & 0x8000), flag_len & 0x7FFF
                ok = (len(data) - 16 == length
                      and fletcher16(data[:14] + data[16:]) == int.from_bytes(data[14:16], "big"))
            if not ok:
                log.write(f"o {now:.6f} 0 nan\n")
                assembling = bytearray()
                continue
            if offset != len(assembling):
                assembling = bytearray()
                if offset != 0:
                    log.write(f"o {now:.6f} 0 nan\n")
                    continue
            assembling += data[16:]
            if not last:
                continue
            try:
                timing = json.loads(assembling)["timing"]
                ts = timing["sampleTimestamp"]
                delay = (now - (ts["seconds"] + ts["nanoseconds"] * 1e-9)) * 1e3
                log.write(f"o {now:.6f} 1 {delay:.3f} {timing['sequenceNumber']}\n")
            except (ValueError, KeyError, TypeError):
                log.write(f"o {now:.6f} 0 nan\n")
            assembling = bytearray()


def viewer(url, logpath):
    host_port, _, path = url.removeprefix("http://").partition("/")
    host, _, port = host_port.partition(":")
    log = open(logpath, "w", buffering=1)
    sock = socket.create_connection((host, int(port)))
    sock.sendall(f"GET /{path} HTTP/1.1\r\nHost: {host_port}\r\n\r\n".encode())
    marker = b"--previsframe"
    tail = b""
    first = True
    while True:
        chunk = sock.recv(1 << 16)
        if not chunk:
            log.write("closed\n")
            return
        buf = tail + chunk
        if first:
            status = buf.split(b"\r\n", 1)[0].decode(errors="replace")
            log.write(f"# {status}\n")
            first = False
        now = time.time()
        for _ in range(buf.count(marker)):
            log.write(f"{now:.6f}\n")
        tail = buf[-(len(marker) - 1):]


def freeport():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    print(s.getsockname()[1])


def pct(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))] if v else float("nan")


def analyse(d):
    samples = []
    for line in open(os.path.join(d, "samples")):
        # "BEFORE AFTER JSON": the status call's start and end; the snapshot is placed between.
        t0, t1, body = line.split(" ", 2)
        try:
            samples.append((0.5 * (float(t0) + float(t1)), json.loads(body)))
        except ValueError:
            pass
    packets = [line.split() for line in open(os.path.join(d, "udp.log"))]
    cases = [line.split() for line in open(os.path.join(d, "cases"))]
    rows = []
    for name, viewers, t0, t1 in cases:
        viewers, t0, t1 = int(viewers), float(t0), float(t1)
        win = [(t, s) for t, s in samples if t0 <= t <= t1]
        (ta, a), (tb, b) = win[0], win[-1]
        span = tb - ta
        shown = (b["framesShown"] - a["framesShown"]) / span
        to_a, to_b = a["trackingOut"], b["trackingOut"]
        tracked = ((to_b["freed"]["packets"] + to_b["lostNotSent"])
                   - (to_a["freed"]["packets"] + to_a["lostNotSent"])) / span
        sent_freed = (to_b["freed"]["packets"] - to_a["freed"]["packets"]) / span
        sent_otio = (to_b["opentrackio"]["samples"] - to_a["opentrackio"]["samples"]) / span
        lost = (to_b["lostNotSent"] - to_a["lostNotSent"]) / span
        f = [p for p in packets if p[0] == "f" and ta <= float(p[1]) <= tb]
        o = [p for p in packets if p[0] == "o" and ta <= float(p[1]) <= tb]
        delays = [float(p[3]) for p in o if p[2] == "1"]
        # Samples lost on the way: gaps in timing.sequenceNumber (one per sample, in order).
        seqs = [int(p[4]) for p in o if p[2] == "1"]
        missing = (max(seqs) - min(seqs) + 1 - len(seqs)) if seqs else 0
        last = [s["trackingOut"]["delayMs"]["last"] for _, s in win]
        web_a, web_b = a["web"], b["web"]
        encoded = web_b["framesEncoded"] - web_a["framesEncoded"]
        sent = web_b["framesSent"] - web_a["framesSent"]
        vdrop = web_b["viewerFramesDropped"] - web_a["viewerFramesDropped"]
        rates = []
        for i in range(viewers):
            times = [float(x) for x in open(os.path.join(d, f"viewer-{name}-{i}.log"))
                     if x[0].isdigit()]
            times = [t for t in times if ta <= t <= tb]
            rates.append(len(times) / span)
        rows.append(dict(
            case=name, viewers=viewers, seconds=span, shown=shown, tracked=tracked,
            sentFreed=sent_freed, sentOtio=sent_otio, lostPerS=lost,
            rxFreed=len(f) / span, badFreed=sum(p[2] != "1" for p in f),
            rxOtio=sum(p[2] == "1" for p in o) / span, badOtio=sum(p[2] != "1" for p in o),
            missingOtio=missing,
            delayMed=statistics.median(delays) if delays else float("nan"),
            delayP95=pct(delays, 0.95), delayMax=max(delays, default=float("nan")),
            statusLastMed=statistics.median(last), statusMax=b["trackingOut"]["delayMs"]["max"],
            fps=statistics.median(s["fps"] for _, s in win),
            renderMs=statistics.median(s["renderMs"] for _, s in win),
            trackMs=statistics.median(s["trackMs"] for _, s in win),
            encodedPerS=encoded / span, sentPerEncode=(sent / encoded) if encoded else 0.0,
            viewerDropped=vdrop, encodeMs=web_b["encodeMs"],
            viewerRates=rates, dropped=to_b["dropped"] - to_a["dropped"],
            failed=to_b["failed"] - to_a["failed"], mode=b["mode"]))
    with open(os.path.join(d, "result.json"), "w") as out:
        json.dump(rows, out)
    for r in rows:
        vr = " ".join(f"{x:.2f}" for x in r["viewerRates"]) or "-"
        print(f"{r['case']}: {r['viewers']} viewer(s), {r['seconds']:.0f} s, mode {r['mode']}\n"
              f"  frames shown/s {r['shown']:.2f} (service fps median {r['fps']:.2f}, "
              f"renderMs {r['renderMs']:.0f}, trackMs {r['trackMs']:.1f}); "
              f"tracked/s {r['tracked']:.2f} (lost, not sent {r['lostPerS']:.2f}/s)\n"
              f"  sent/s FreeD {r['sentFreed']:.2f} OpenTrackIO {r['sentOtio']:.2f}; "
              f"received/s FreeD {r['rxFreed']:.2f} (bad {r['badFreed']}) OpenTrackIO "
              f"{r['rxOtio']:.2f} (bad {r['badOtio']}, sequence gaps {r['missingOtio']}); "
              f"dropped {r['dropped']} failed "
              f"{r['failed']}\n"
              f"  delay capture->receipt (OpenTrackIO sampleTimestamp) median "
              f"{r['delayMed']:.1f} ms p95 {r['delayP95']:.1f} max {r['delayMax']:.1f}; "
              f"status delayMs last median {r['statusLastMed']:.1f} max {r['statusMax']:.1f}\n"
              f"  web: encoded/s {r['encodedPerS']:.2f}, sent per encode "
              f"{r['sentPerEncode']:.2f}, encodeMs {r['encodeMs']:.2f}, viewer frames dropped "
              f"{r['viewerDropped']}; each viewer's frames/s {vr}")


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    try:
        {"receive": receive, "viewer": viewer, "freeport": freeport, "analyse": analyse}[cmd](*args)
    except KeyboardInterrupt:
        pass
