"""pysoem (SOEM, an independent master) against segments served by the oxicat package."""

import os
import pathlib
import re
import time

import pytest

import oxicat

pysoem = pytest.importorskip("pysoem")

STATE_TIMEOUT_US = 5_000_000
RECV_TIMEOUT_US = 100_000


def reference_esi(name):
    """A file of the reference ESI set (``$OXICAT_REFERENCE/esi``); skips without it."""
    ref = os.environ.get("OXICAT_REFERENCE")
    path = pathlib.Path(ref, "esi", name) if ref else None
    if path is None or not path.is_file():
        if os.environ.get("CI"):
            pytest.fail(f"reference ESI {name} missing (OXICAT_REFERENCE={ref!r})")
        pytest.skip(f"reference ESI {name} missing (set OXICAT_REFERENCE)")
    return path


def scan(iface):
    master = pysoem.Master()
    master.open(iface)
    # SOEM waits briefly for the first answers: the segment may still be settling.
    for _ in range(5):
        if master.config_init() > 0:
            break
        time.sleep(0.2)
    return master


def cycle(master, n=1):
    wkc = 0
    for _ in range(n):
        master.send_processdata()
        wkc = master.receive_processdata(RECV_TIMEOUT_US)
        time.sleep(0.001)
    return wkc


def to_op(master):
    master.config_map()
    assert master.state_check(pysoem.SAFEOP_STATE, STATE_TIMEOUT_US) == pysoem.SAFEOP_STATE
    master.state = pysoem.OP_STATE
    cycle(master)
    master.write_state()
    for _ in range(500):
        cycle(master)
        if master.state_check(pysoem.OP_STATE, 10_000) == pysoem.OP_STATE:
            return
    pytest.fail(f"not OP: {[hex(s.state) for s in master.slaves]}")


def test_pysoem_scans_and_exchanges_process_data(segment, veth):
    master = scan(veth[0])
    try:
        assert len(master.slaves) == len(segment) == 2
        assert segment.slaves == ["demo", "demo"]
        for i, s in enumerate(master.slaves):
            assert (s.man, s.id, s.rev) == segment.identity(i)
        to_op(master)
        assert [segment.al_state(i) for i in range(len(segment))] == ["OP", "OP"]
        expected_wkc = master.expected_wkc if hasattr(master, "expected_wkc") else None
        for i, s in enumerate(master.slaves):
            pattern = bytes((0x5A + 17 * i + k) & 0xFF for k in range(len(s.output)))
            s.output = pattern
        wkc = cycle(master, 20)
        if expected_wkc is not None:
            assert wkc == expected_wkc
        for i, s in enumerate(master.slaves):
            assert len(s.output) > 0
            assert segment.read_outputs(i) == bytes(s.output), f"slave {i}"
            assert len(segment.read_inputs(i)) == len(s.input)
    finally:
        master.close()


def test_faults_frame_loss_link_down_watchdog(segment, veth):
    master = scan(veth[0])
    try:
        to_op(master)
        good = cycle(master, 5)
        assert good > 0
        # Frame loss: the next frames never reach a slave, then the segment answers again.
        segment.drop_frames(3)
        lost = [cycle(master) for _ in range(3)]
        assert all(w <= 0 for w in lost), lost
        assert cycle(master, 3) == good
        # Link down at the master port: nothing comes back while it is pulled, and the
        # slaves' process-data watchdog (no outputs for longer than it) drops them to
        # SAFEOP with an error.
        segment.set_cable(0, 0, plugged=False)
        assert cycle(master) <= 0
        time.sleep(0.5)
        assert all(segment.al_state(i) == "SAFEOP+ERR" for i in range(len(segment)))
        segment.set_cable(0, 0, plugged=True)
        assert cycle(master) > 0
    finally:
        master.close()


def test_injected_watchdog_expiry(segment, veth):
    master = scan(veth[0])
    try:
        with pytest.raises(oxicat.OxicatError, match="not running"):
            segment.expire_watchdog(0)
        to_op(master)
        good = cycle(master, 5)
        segment.expire_watchdog(1)
        cycle(master, 20)
        master.read_state()
        s = master.slaves[1]
        assert s.state == pysoem.SAFEOP_STATE | pysoem.STATE_ERROR, hex(s.state)
        assert s.al_status == 0x001B
        assert segment.al_state(1) == "SAFEOP+ERR"
        assert segment.al_state(0) == "OP"
        # The master acknowledges and takes the slave back to OP.
        s.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK
        s.write_state()
        cycle(master, 5)
        s.state = pysoem.OP_STATE
        s.write_state()
        for _ in range(200):
            if cycle(master) == good and segment.al_state(1) == "OP":
                break
        assert segment.al_state(1) == "OP"
    finally:
        master.close()


def test_twin_of_a_vendor_esi(veth):
    esi = reference_esi("soes-xmc4300_slavedemo-esi.xml")
    text = esi.read_text(errors="replace")
    vendor = int(re.search(r"<Vendor>\s*<Id>\s*#x([0-9A-Fa-f]+)", text).group(1), 16)
    with oxicat.Segment(esi=[str(esi)], iface=veth[1]) as seg:
        assert len(seg) == 1
        master = scan(veth[0])
        try:
            s = master.slaves[0]
            assert (s.man, s.id, s.rev) == (vendor, 0x12783456, 1) == seg.identity(0)
            to_op(master)
            assert seg.al_state(0) == "OP"
            s.output = bytes(range(1, len(s.output) + 1))
            cycle(master, 20)
            assert seg.read_outputs(0) == bytes(s.output)
        finally:
            master.close()


def test_udp_segment_and_errors():
    with oxicat.Segment(["demo:1"]) as seg:
        assert seg.address.startswith("127.0.0.1:")
        assert seg.running
        assert seg.slaves == ["demo"]
        assert seg.al_state(0) == "INIT"
        with pytest.raises(IndexError):
            seg.read_outputs(5)
        # No SyncManager is configured before a master does: no process data yet.
        assert seg.read_inputs(0) == b""
        with pytest.raises(ValueError, match="0 input byte"):
            seg.write_inputs(0, b"x")
        seg.drop_frames(1)
        with pytest.raises(oxicat.OxicatError):
            seg.set_cable(0, 7)
    assert not seg.running
    seg.stop()
    with pytest.raises(oxicat.OxicatError, match="nosuch"):
        oxicat.Segment(["nosuch:1"])
    with pytest.raises(ValueError):
        oxicat.Segment(["demo"], slowdown=0)
