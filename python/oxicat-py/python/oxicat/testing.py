"""Helpers for tests that serve a segment to a raw-Ethernet master (SOEM/pysoem)."""

import contextlib
import itertools
import os
import shutil
import subprocess

_counter = itertools.count()


def can_make_veth():
    """Whether this process can create a veth pair (root and ``ip``)."""
    return os.geteuid() == 0 and shutil.which("ip") is not None


def _ip(*args):
    subprocess.run(["ip", *args], check=True, capture_output=True)


@contextlib.contextmanager
def veth_pair(prefix="oxpy"):
    """A veth pair ``(master_end, segment_end)``, both up, removed afterwards.

    Serve the segment on ``segment_end`` (``Segment(..., iface=segment_end)``) and open the
    master on ``master_end``. Needs root (CAP_NET_ADMIN).
    """
    n = f"{os.getpid() % 100000}{next(_counter)}"
    master, segment = f"{prefix}m{n}"[:15], f"{prefix}s{n}"[:15]
    _ip("link", "add", master, "type", "veth", "peer", "name", segment)
    try:
        for end in (master, segment):
            # No IPv6 chatter (router solicitations) on the EtherCAT link.
            with contextlib.suppress(OSError):
                with open(f"/proc/sys/net/ipv6/conf/{end}/disable_ipv6", "w") as f:
                    f.write("1")
            _ip("link", "set", end, "up")
        yield master, segment
    finally:
        with contextlib.suppress(subprocess.CalledProcessError):
            _ip("link", "del", master)
