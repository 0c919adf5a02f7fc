#!/usr/bin/env python3
"""SOEM (through pysoem) against a segment served by `oxicat sim --iface`.

Run by crates/oxicat/tests/soem_netns.rs, which serves the segment on one end of a veth
pair and writes what every slave should show (from the device's definition and ESI) to a
JSON file:

    python soem_check.py <interface> <spec.json>

Every check prints one line

    CHECK <check> <slave position> PASS|FAIL <detail>

so that the Rust test reports each check separately; `INFO` lines say what happened.
The exit code is 0 when the script got through (failed checks included) and non-zero
only when it could not run at all (no pysoem, no interface, no slaves).
"""

import json
import struct
import sys
import time

import pysoem

# SDO abort codes (ETG.1000.6 table 41).
ABORT_NO_OBJECT = 0x06020000
ABORT_READ_ONLY = 0x06010002
# AL status code of the SM watchdog (ETG.1000.6 table 11).
AL_SM_WATCHDOG = 0x001B
# ESC registers (ET1100 datasheet section II).
REG_DC_ACTIVATION = 0x0980
REG_DC_NEXT_SYNC0 = 0x0990
REG_DC_SYNC0_CYCLE = 0x09A0
# Receive timeout for one process-data frame (µs): generous, the simulator is a debug
# build on a loaded machine and can stall for tens of ms; a frame not back by then counts
# as a working-counter error.
RECV_TIMEOUT_US = 500_000
# SM watchdog time set by the master (0x0420): 100 ms is the ESC's default, but a
# debug-build simulator on a loaded machine can stall that long between two frames; the
# watchdog path is the same with 500 ms.
WATCHDOG_MS = 500
# Waiting for a state (µs).
STATE_TIMEOUT_US = 5_000_000
# The least time SOEM waits for a datagram of a slowed-down segment (µs of wall time): the
# host's own stalls (see stretch_soem_timeouts).
HOST_STALL_US = 250_000
# How long the scan waits for every slave to reach PREOP (s of the segment's time): a
# board image boots for up to 0.7 s of its time before its mailbox runs.
BOOT_TIMEOUT_S = 5
# A scan whose slaves are not in PREOP after this long (s of the segment's time) is done
# again.
PREOP_RESCAN_S = 2
# Attempts of an SDO read that got no reply in SOEM's mailbox timeout (700 ms, the
# master's sdo_read_timeout, K times that for a segment slowed down K times): a debug-build simulator serving a leg node on a machine loaded by a
# parallel build has missed it (WkcError on a 0x1018 read, twice in about twenty CI
# runs). A reply that is wrong, or none in three attempts, still fails the check.
SDO_READ_ATTEMPTS = 3


def check(name, pos, ok, detail=""):
    """Prints one check result."""
    print(f"CHECK {name} {pos} {'PASS' if ok else 'FAIL'} {detail}".rstrip(), flush=True)


def info(text):
    print(f"INFO {text}", flush=True)


def state_name(s):
    names = {
        pysoem.NONE_STATE: "NONE",
        pysoem.INIT_STATE: "INIT",
        pysoem.PREOP_STATE: "PREOP",
        pysoem.BOOT_STATE: "BOOT",
        pysoem.SAFEOP_STATE: "SAFEOP",
        pysoem.OP_STATE: "OP",
    }
    base = names.get(s & 0x0F, f"0x{s & 0x0F:02X}")
    return base + ("+ERR" if s & pysoem.STATE_ERROR else "")


def sdo_abort(slave, fn):
    """Runs an SDO transfer that must be refused; returns (abort code or None, what
    happened instead)."""
    try:
        result = fn()
    except pysoem.SdoError as e:
        return e.abort_code, f"SdoError 0x{e.abort_code:08X} ({e.desc})"
    except Exception as e:  # noqa: BLE001 - any other outcome is reported as is
        return None, f"{type(e).__name__}: {e}"
    return None, f"no abort, transfer succeeded ({result!r})"


def sdo_read(pos, slave, index, sub, size=0):
    """An SDO read, tried again (up to SDO_READ_ATTEMPTS) when no reply came in time
    (pysoem.WkcError); every other outcome is final."""
    for attempt in range(1, SDO_READ_ATTEMPTS + 1):
        try:
            return slave.sdo_read(index, sub, size)
        except pysoem.WkcError:
            if attempt == SDO_READ_ATTEMPTS:
                raise
            info(f"slave {pos}: no reply to the read of 0x{index:04X}:{sub:02X} in time "
                 f"(attempt {attempt}); again")


def sdo_checks(pos, slave, spec):
    """Identity, device name, abort codes and a write/read-back in PREOP."""
    try:
        got = [struct.unpack("<I", sdo_read(pos, slave, 0x1018, sub))[0] for sub in (1, 2, 3)]
        want = [spec["vendor_id"], spec["product_code"], spec["revision"]]
        check("sdo_read_identity", pos, got == want,
              f"0x1018:01..03 = {[hex(v) for v in got]}, want {[hex(v) for v in want]}")
    except Exception as e:  # noqa: BLE001
        check("sdo_read_identity", pos, False, f"{type(e).__name__}: {e}")

    for index, key in ((0x1008, "device_name"), (0x1009, "hw_version"), (0x100A, "sw_version")):
        want = spec[key]
        try:
            got = sdo_read(pos, slave, index, 0, 1024).rstrip(b"\0").decode("latin-1")
            check("sdo_read_strings", pos, got == want,
                  f"0x{index:04X} = {got!r}, want {want!r}")
        except Exception as e:  # noqa: BLE001
            check("sdo_read_strings", pos, False, f"0x{index:04X}: {type(e).__name__}: {e}")

    # The PDO assignment (0x1C12 outputs, 0x1C13 inputs) as the ESI's defaults say.
    for index, key in ((0x1C12, "rx_assign"), (0x1C13, "tx_assign")):
        if key not in spec:
            continue
        want = spec[key]
        try:
            n = sdo_read(pos, slave, index, 0)[0]
            got = [struct.unpack("<H", sdo_read(pos, slave, index, k)[:2])[0]
                   for k in range(1, n + 1)]
            check("sdo_pdo_assign", pos, got == want,
                  f"0x{index:04X} = {[hex(v) for v in got]}, the ESI says "
                  f"{[hex(v) for v in want]}")
        except Exception as e:  # noqa: BLE001
            check("sdo_pdo_assign", pos, False, f"0x{index:04X}: {type(e).__name__}: {e}")

    missing = spec["missing_index"]
    code, what = sdo_abort(slave, lambda: slave.sdo_read(missing, 0))
    check("sdo_abort_missing_object", pos, code == ABORT_NO_OBJECT,
          f"read 0x{missing:04X}:00: {what}, want SdoError 0x{ABORT_NO_OBJECT:08X}")

    code, what = sdo_abort(slave, lambda: slave.sdo_write(0x1018, 1, struct.pack("<I", 0x12345678)))
    after = None
    try:
        after = struct.unpack("<I", slave.sdo_read(0x1018, 1))[0]
    except Exception as e:  # noqa: BLE001
        what += f"; read back failed: {type(e).__name__}: {e}"
    check("sdo_abort_read_only", pos, code == ABORT_READ_ONLY and after == spec["vendor_id"],
          f"write 0x1018:01: {what}, want SdoError 0x{ABORT_READ_ONLY:08X}; "
          f"0x1018:01 afterwards = {after if after is None else hex(after)}")

    rw = spec.get("rw")
    if rw is None:
        check("sdo_write_read_back", pos, True, "skipped: the definition has no writable "
              "integer entry in PREOP")
        return
    idx, sub, size, value = rw["index"], rw["sub"], rw["size"], rw["value"]
    fmt = {1: "<B", 2: "<H", 4: "<I"}[size]
    where = f"0x{idx:04X}:{sub:02X}"
    try:
        old = slave.sdo_read(idx, sub)
        slave.sdo_write(idx, sub, struct.pack(fmt, value))
        got = struct.unpack(fmt, slave.sdo_read(idx, sub)[:size])[0]
        slave.sdo_write(idx, sub, old)
        restored = slave.sdo_read(idx, sub) == old
        check("sdo_write_read_back", pos, got == value and restored,
              f"{where}: wrote {value}, read {got}; old value restored: {restored}")
    except Exception as e:  # noqa: BLE001
        check("sdo_write_read_back", pos, False, f"{where}: {type(e).__name__}: {e}")


class Cycler:
    """Process-data cycles at a fixed period, counting working-counter errors."""

    def __init__(self, master, period_s, expected_wkc, slow=1):
        self.master = master
        # The receive timeout in the segment's time, as SOEM's (stretch_soem_timeouts).
        self.recv_timeout_us = RECV_TIMEOUT_US * slow
        self.expected_wkc = expected_wkc
        self.period = period_s
        self.next = time.monotonic()
        self.cycles = 0
        self.wkc_errors = 0
        self.first_error = None

    def cycle(self):
        self.master.send_processdata()
        wkc = self.master.receive_processdata(self.recv_timeout_us)
        self.cycles += 1
        # Nothing mapped: SOEM sends no frame and receive reports EC_NOFRAME (-1); the
        # cycle is then only the period.
        if wkc == -1 and self.expected_wkc == 0 and self.master.expected_wkc == 0:
            pass
        elif wkc != self.expected_wkc:
            self.wkc_errors += 1
            if self.first_error is None:
                self.first_error = f"cycle {self.cycles}: wkc {wkc}, expected {self.expected_wkc}"
        self.next += self.period
        delay = self.next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        else:
            # Behind (a loaded machine): restart the schedule instead of bursting.
            self.next = time.monotonic()

    def reset_counts(self):
        self.cycles = 0
        self.wkc_errors = 0
        self.first_error = None


def all_in(master, want):
    """Reads every slave's AL status; whether all are in `want` (error flag included)."""
    master.read_state()
    return all(s.state == want for s in master.slaves)


def reach(master, cycler, want, timeout_s):
    """Requests `want` for all slaves (again every 100 ms, as masters do), cycling process
    data while waiting; returns whether all got there."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        master.state = want
        master.write_state()
        for _ in range(100):
            cycler.cycle()
            if all_in(master, want):
                return True
    return all_in(master, want)


def fprd(slave, address, size):
    """An FPRD with SOEM's datagram timeout (pysoem's `_fprd` defaults to a fixed 2 ms,
    whatever `stretch_soem_timeouts` set)."""
    return slave._fprd(address, size, pysoem.settings.timeouts.ret)


def dc_checks(pos, slave, cycle_ns, slow=1):
    """SYNC0 on: 0x1C32:01 = DC SYNC0, 0x1C32:02 = the SYNC0 cycle, the ESC's SYNC0 unit
    activated with our cycle and its next-pulse time advancing by whole cycles. The wait
    between the two reads of the next pulse is at least three cycles of the segment's time
    (a segment slowed down K times needs K times the wall time: 20 ms at K = 30 was less
    than one 1 ms cycle, so the pulse sometimes had not moved)."""
    wait_s = max(0.02, 3 * cycle_ns * 1e-9 * slow)
    try:
        mode = struct.unpack("<H", slave.sdo_read(0x1C32, 1))[0]
        cyc = struct.unpack("<I", slave.sdo_read(0x1C32, 2))[0]
        act = fprd(slave, REG_DC_ACTIVATION, 2)
        sync0_cycle = struct.unpack("<I", fprd(slave, REG_DC_SYNC0_CYCLE, 4))[0]
        t0 = struct.unpack("<Q", fprd(slave, REG_DC_NEXT_SYNC0, 8))[0]
        time.sleep(wait_s)
        t1 = struct.unpack("<Q", fprd(slave, REG_DC_NEXT_SYNC0, 8))[0]
        adv = t1 - t0
        ok = (mode == 2 and cyc == cycle_ns and act[1] & 0x03 == 0x03
              and sync0_cycle == cycle_ns and adv > 0 and adv % cycle_ns == 0)
        check("dc_sync0", pos, ok,
              f"0x1C32:01 = {mode} (want 2), 0x1C32:02 = {cyc} (want {cycle_ns}), "
              f"0x0981 = 0x{act[1]:02X}, 0x09A0 = {sync0_cycle}, next SYNC0 advanced {adv} ns "
              f"in {wait_s * 1000:.0f} ms")
    except Exception as e:  # noqa: BLE001
        check("dc_sync0", pos, False, f"{type(e).__name__}: {e}")


SYNC_MODES = {0: "free run", 1: "SM-synchronous", 2: "DC SYNC0", 3: "DC SYNC1"}


def set_sync_mode(pos, slave, mode):
    """Sets 0x1C32:01 to `mode` in PREOP unless it is already (SOEM writes no 0x1C32)."""
    try:
        got = struct.unpack("<H", sdo_read(pos, slave, 0x1C32, 1)[:2])[0]
        if got != mode:
            slave.sdo_write(0x1C32, 1, struct.pack("<H", mode))
            info(f"slave {pos}: 0x1C32:01 was {got}, set to {mode} ({SYNC_MODES[mode]})")
        else:
            info(f"slave {pos}: 0x1C32:01 = {got} ({SYNC_MODES[mode]}) already")
    except Exception as e:  # noqa: BLE001 - the check in OP reports the outcome
        info(f"slave {pos}: setting 0x1C32:01 = {mode}: {type(e).__name__}: {e}")


def sync_mode_check(pos, slave, mode):
    """In OP: 0x1C32:01 is `mode` and 0x1C32:04 (supported modes) offers it."""
    try:
        got = struct.unpack("<H", sdo_read(pos, slave, 0x1C32, 1)[:2])[0]
        supported = struct.unpack("<H", sdo_read(pos, slave, 0x1C32, 4)[:2])[0]
        ok = got == mode and supported & (1 << mode) != 0
        check("sync_mode", pos, ok,
              f"0x1C32:01 = {got} (want {mode}, {SYNC_MODES[mode]}), "
              f"0x1C32:04 = 0x{supported:04X}")
    except Exception as e:  # noqa: BLE001
        check("sync_mode", pos, False, f"{type(e).__name__}: {e}")


def stretch_soem_timeouts(master, slow):
    """Multiplies SOEM's timeouts (pysoem.settings.timeouts and the master's SDO timeouts,
    µs of wall time) by `slow`, and gives every datagram at least HOST_STALL_US.

    A segment served K times slower than real time answers K times later: SOEM's 2 ms for a
    datagram (EC_TIMEOUTRET: a state read, a mailbox poll) is 0.1 ms of a segment served 20
    times slower, less than an emulated board takes for a burst of its firmware (the CiA402
    joint's 180 µs SYNC0 handler), so frames came back after SOEM had given up: state reads
    in OP failed at random (45 of 300 reads of 0x0130), and a mailbox read that came back
    late made SOEM ask the slave to repeat its reply, which the next SDO then took for its
    own (PacketError, "unexpected frame"). Stretched by K, every SOEM timeout is the same in
    the segment's time as on a real one; the floor covers the host, which on a 2-core
    machine at a load of 10 held single frames for up to 200 ms of wall time whatever K
    was. (SOEM asks for a repeat when a mailbox read is lost: ecx_mbxreceive toggles the
    SM1 repeat request.)
    A segment in real time (K = 1, host-compiled firmware) keeps SOEM's own timeouts.
    """
    if slow <= 1:
        return
    t = pysoem.settings.timeouts
    for name in ("ret", "safe", "eeprom", "tx_mailbox", "rx_mailbox", "state"):
        setattr(t, name, max(getattr(t, name) * slow, HOST_STALL_US))
    master.sdo_read_timeout *= slow
    master.sdo_write_timeout *= slow
    info(f"SOEM timeouts stretched {slow} times: datagram {t.ret} µs, SDO "
         f"{master.sdo_read_timeout} µs")


def scan_to_preop(master, slow):
    """Scans (config_init, which requests PREOP) and waits until every slave found is in
    PREOP (or refused it with the error flag), asking again every 100 ms of the segment's
    time as masters do; returns how many slaves the last scan found.

    A board still booting (an emulated image's calibration, power-on wait and ESC set-up
    take up to 0.7 s of its time, K times that in wall time when served `--slowdown K`)
    has no mailbox yet: SDOs sent before it answers PREOP time out. Nothing found (a master
    scans again when nothing answered in time), or not in PREOP within PREOP_RESCAN_S of the
    segment's time (a LAN9252 reset by its booting firmware drops the address the scan gave
    it): scan again, up to BOOT_TIMEOUT_S of the segment's time (at least 10 s of wall
    time)."""
    start = time.monotonic()
    deadline = start + max(10.0, BOOT_TIMEOUT_S * slow)
    attempt = 0
    while True:
        attempt += 1
        n = master.config_init()
        info(f"config_init (attempt {attempt}) found {n} slaves")
        if n > 0:
            rescan = time.monotonic() + PREOP_RESCAN_S * slow
            polls = 0
            while time.monotonic() < min(rescan, deadline):
                master.read_state()
                # In PREOP, or refused with the error flag: the firmware answered.
                if all(s.state & 0x0F == pysoem.PREOP_STATE or s.state & pysoem.STATE_ERROR
                       for s in master.slaves):
                    info(f"all {n} slaves answered the PREOP request "
                         f"{time.monotonic() - start:.1f} s after the first scan: "
                         f"{', '.join(state_name(s.state) for s in master.slaves)}")
                    return n
                polls += 1
                if polls % 10 == 0:
                    master.state = pysoem.PREOP_STATE
                    master.write_state()
                time.sleep(0.01 * slow)
        else:
            time.sleep(1.0)
        if time.monotonic() >= deadline:
            info(f"not all in PREOP {time.monotonic() - start:.1f} s after the first scan")
            return n


def main():
    iface, spec_path = sys.argv[1], sys.argv[2]
    with open(spec_path, encoding="utf-8") as f:
        spec = json.load(f)
    want = spec["slaves"]
    cycles = spec["cycles"]
    cycle_ns = spec["cycle_ns"]
    # A segment served slowed down (`--slowdown K`, emulated board images) runs its clock K
    # times slower than real time: the script's own cycle and waits stretch by K so that
    # they stay the same in the segment's time, and so do SOEM's timeouts.
    slow = spec.get("slowdown", 1)
    # The SM watchdog time (segment time); a slowed-down segment, which does not stall like a
    # debug build, takes the ESC's default 100 ms so the wait for it stays short in wall time.
    watchdog_ms = spec.get("watchdog_ms", WATCHDOG_MS)

    master = pysoem.Master()
    stretch_soem_timeouts(master, slow)
    master.open(iface)
    try:
        n = scan_to_preop(master, slow)
        check("scan_count", 0, n == len(want), f"found {n}, want {len(want)}")
        if n != len(want):
            return
        for pos, (slave, s) in enumerate(zip(master.slaves, want)):
            got = (slave.man, slave.id, slave.rev)
            exp = (s["vendor_id"], s["product_code"], s["revision"])
            check("scan_identity", pos, got == exp,
                  f"vendor/product/revision {tuple(hex(v) for v in got)}, "
                  f"want {tuple(hex(v) for v in exp)}")
            # SOEM names a slave by SII string 1 (cut at EC_MAXNAME = 40 characters).
            # SOEM copies at most 40 bytes and the C string ends at a NUL byte.
            raw = s["order_code"].encode("latin-1", "replace")[:40].split(b"\0")[0]
            try:
                name = slave.name
                ok = name == s["order_code"][:40]
                check("scan_name", pos, ok, f"SOEM name {name!r}, want the ESI Type "
                      f"(order code) {s['order_code']!r}")
            except UnicodeDecodeError as e:
                # pysoem decodes the name as UTF-8: a device whose string 1 is not text
                # (HBM's ClipX keeps a bitmap there) fails so with the device itself.
                try:
                    raw.decode("utf-8")
                    ok = False
                except UnicodeDecodeError:
                    ok = True
                check("scan_name", pos, ok, f"pysoem cannot decode the name ({e}); "
                      f"SII string 1 starts {raw!r}")

        # Slaves without a slave stack (served by their ESC alone, as simple terminals
        # are) have no mailbox: no SDO, DC-by-CoE or AL-status checks for them.
        for pos, (slave, s) in enumerate(zip(master.slaves, want)):
            if s.get("stack", True):
                sdo_checks(pos, slave, s)

        # A slave run in a mode other than DC (`sync_mode`, the 0x1C32:01 code): SOEM's
        # configuration writes no 0x1C32, so an application sets the mode in PREOP where
        # the device's default differs (an SM-synchronous-only slave already defaults to it).
        sync_slaves = [pos for pos, s in enumerate(want) if "sync_mode" in s]
        for pos in sync_slaves:
            set_sync_mode(pos, master.slaves[pos], want[pos]["sync_mode"])

        dc_slaves = [pos for pos, s in enumerate(want) if s["dc"]]
        if dc_slaves:
            found = master.config_dc()
            info(f"config_dc: DC slaves found: {found}")
            for pos in dc_slaves:
                master.slaves[pos].dc_sync(True, cycle_ns)
        for slave in master.slaves:
            slave.set_watchdog("processdata", watchdog_ms)
        size = master.config_map()
        info(f"config_map: {size} bytes of process data, expected wkc {master.expected_wkc}")
        for pos, (slave, s) in enumerate(zip(master.slaves, want)):
            if "out_bytes" not in s:
                continue
            got = (len(slave.output), len(slave.input))
            exp = (s["out_bytes"], s["in_bytes"])
            check("pd_map", pos, got == exp,
                  f"SOEM mapped {got[0]} output and {got[1]} input bytes, want {exp[0]} "
                  f"and {exp[1]} (the ESI's default PDO assignment)")
        state = master.state_check(pysoem.SAFEOP_STATE, STATE_TIMEOUT_US * slow)
        master.read_state()
        for pos, slave in enumerate(master.slaves):
            check("to_safeop", pos, slave.state == pysoem.SAFEOP_STATE,
                  f"{state_name(slave.state)}, AL status 0x{slave.al_status:04X}")
        if state != pysoem.SAFEOP_STATE:
            # What SOEM left in the process-data SMs (start, length, control, status,
            # activate, PDI control), for the refusal's reason.
            for pos, slave in enumerate(master.slaves):
                for sm in (2, 3):
                    try:
                        r = fprd(slave, 0x0800 + 8 * sm, 8)
                        info(f"slave {pos} SM{sm}: start 0x{r[0] | r[1] << 8:04X} length "
                             f"{r[2] | r[3] << 8} control 0x{r[4]:02X} activate 0x{r[6]:02X}")
                    except Exception as e:  # noqa: BLE001
                        info(f"slave {pos} SM{sm}: {type(e).__name__}: {e}")
            return

        # The working counter the slaves answer an LRW with: 2 for each slave with outputs
        # (written), 1 for each with inputs (read). SOEM's own figure can be lower: its
        # legacy mapping counts no output WKC for a segment whose outputs are bit-packed
        # into one byte (a single EL2002), which the terminal itself answers with 2.
        if all("out_bytes" in s for s in want):
            hw_wkc = sum(2 * (s["out_bytes"] > 0) + (s["in_bytes"] > 0) for s in want)
            if hw_wkc != master.expected_wkc:
                info(f"SOEM expects wkc {master.expected_wkc}; the slaves answer {hw_wkc} "
                     f"(2 per slave with outputs, 1 per slave with inputs): cycling "
                     f"against {hw_wkc}")
        else:
            hw_wkc = master.expected_wkc
        cycler = Cycler(master, cycle_ns / 1e9 * slow, hw_wkc, slow)
        reach(master, cycler, pysoem.OP_STATE, 10.0 * slow)
        for pos, slave in enumerate(master.slaves):
            check("to_op", pos, slave.state == pysoem.OP_STATE,
                  f"{state_name(slave.state)}, AL status 0x{slave.al_status:04X}")

        cycler.reset_counts()
        start = time.monotonic()
        for _ in range(cycles):
            cycler.cycle()
        took = time.monotonic() - start
        master.read_state()
        for pos, slave in enumerate(master.slaves):
            ok = (cycler.cycles == cycles and cycler.wkc_errors == 0
                  and slave.state == pysoem.OP_STATE)
            check("pdo_exchange", pos, ok,
                  f"{cycler.cycles} cycles in {took:.1f} s, {cycler.wkc_errors} wkc errors "
                  f"({cycler.first_error or 'none'}), state {state_name(slave.state)} "
                  f"AL status 0x{slave.al_status:04X}")

        for pos in dc_slaves:
            dc_checks(pos, master.slaves[pos], cycle_ns, slow)
            for _ in range(20):
                cycler.cycle()
        for pos in sync_slaves:
            sync_mode_check(pos, master.slaves[pos], want[pos]["sync_mode"])
            for _ in range(20):
                cycler.cycle()

        # The SM watchdog: no process data for three times its time, and longer (up to
        # 10 s) while the simulator, late on a loaded machine, has not got there yet. It
        # guards the outputs' sync manager where its control byte enables it, and it is the
        # slave's firmware that leaves OP when it expires: slaves without outputs, without
        # the watchdog bit or without a stack are not checked.
        wd = [pos for pos, s in enumerate(want) if s.get("watchdog", True)]
        if not wd:
            info("no slave with an output SM watchdog and a stack: the watchdog path does "
                 "not apply")
            master.state = pysoem.INIT_STATE
            master.write_state()
            master.state_check(pysoem.INIT_STATE, STATE_TIMEOUT_US * slow)
            info("done")
            return
        stopped = time.monotonic()
        time.sleep(3 * watchdog_ms / 1000 * slow)
        def wd_tripped():
            master.read_state()
            return all(master.slaves[pos].state == pysoem.SAFEOP_STATE | pysoem.STATE_ERROR
                       for pos in wd)
        while not wd_tripped() and time.monotonic() - stopped < 10 * slow:
            time.sleep(0.1)
        waited_ms = round((time.monotonic() - stopped) * 1000)
        for pos in wd:
            slave = master.slaves[pos]
            ok = (slave.state == pysoem.SAFEOP_STATE | pysoem.STATE_ERROR
                  and slave.al_status == AL_SM_WATCHDOG)
            check("watchdog_safeop_err", pos, ok,
                  f"after {waited_ms} ms without process data: {state_name(slave.state)}, "
                  f"AL status 0x{slave.al_status:04X} (want SAFEOP+ERR 0x{AL_SM_WATCHDOG:04X})")
        # Acknowledge (SAFEOP + ack bit) until the error flag is gone (SOEM's state_check
        # ignores the flag, so read the states).
        deadline = time.monotonic() + STATE_TIMEOUT_US / 1e6 * slow
        while time.monotonic() < deadline:
            for slave in master.slaves:
                slave.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK
                slave.write_state()
            time.sleep(0.01)
            if all_in(master, pysoem.SAFEOP_STATE):
                break
        acked = [(s.state, s.al_status) for s in master.slaves]
        cycler.reset_counts()
        reach(master, cycler, pysoem.OP_STATE, 10.0 * slow)
        for pos in wd:
            slave = master.slaves[pos]
            ok = acked[pos][0] == pysoem.SAFEOP_STATE and slave.state == pysoem.OP_STATE
            check("watchdog_ack_to_op", pos, ok,
                  f"after the ack: {state_name(acked[pos][0])} (AL status "
                  f"0x{acked[pos][1]:04X}), then {state_name(slave.state)}")

        master.state = pysoem.INIT_STATE
        master.write_state()
        master.state_check(pysoem.INIT_STATE, STATE_TIMEOUT_US * slow)
    finally:
        master.close()
    info("done")


if __name__ == "__main__":
    main()
