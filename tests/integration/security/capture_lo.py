#!/usr/bin/env python3
"""Captures every frame on the loopback interface into FILE until SIGTERM/SIGINT (root:
AF_PACKET). No tcpdump on the machine; the security test only needs the raw bytes.
usage: capture_lo.py FILE READY_FILE"""
import signal
import socket
import sys

out_path, ready_path = sys.argv[1], sys.argv[2]
ETH_P_ALL = 0x0003
sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
sock.bind(("lo", 0))
sock.settimeout(0.2)
running = True


def stop(*_):
    global running
    running = False


signal.signal(signal.SIGTERM, stop)
signal.signal(signal.SIGINT, stop)
frames = 0
with open(out_path, "wb") as out:
    open(ready_path, "w").close()
    while running:
        try:
            frame = sock.recv(65535)
        except socket.timeout:
            continue
        out.write(len(frame).to_bytes(4, "little") + frame)
        frames += 1
print(f"capture_lo: {frames} frames", file=sys.stderr)
