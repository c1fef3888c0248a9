#!/usr/bin/env python3
"""CANopen interoperability against python `canopen` (a CANopen stack not written here), over
python-can's udp_multicast bus, which can-transport speaks as `pycan-udp:GROUP:PORT`.

  drive   CiA 402 drives as python canopen LocalNodes with the object dictionary of the EDS
          (SDO server, NMT slave, heartbeat producer, EMCY producer, PDO maps: python canopen's);
          the CiA 402 device state machine and an ideal CSP axis are the lines below. drive-io
          (`drive-io-interop`) configures and runs them. With --cells, one CiA 404 load cell per
          drive (LocalNodes 33.. from config/eds/crs-load-cell.eds) reports the cable force
          3000 N + 100 N x cable in its process value 0x9130sub1 (0.1 N); --swap N makes drive N
          answer as another product (0x1018sub2 = 0x00003000).
  master  a python canopen master (RemoteNodes from the same EDS) configures and drives this
          project's `winch-emulator`: NMT, SDO configuration and aborts, its own PDO mapping
          (different from drive-io's), SYNC, CiA 402 enable, motion, quick stop, EMCY
          (following error), heartbeat loss at the drive (0x1016 -> 0x6007).
  dcf     python canopen imports the DCFs drive-io wrote and checks the configured values
          (signed values such as 0x607D read back signed).

Run by tools/canopen-interop.sh. Exit status 0 iff every check passed.
"""
import argparse
import math
import struct
import sys
import threading
import time

import canopen
from canopen.sdo import SdoAbortedError

SW = {"SOD": 0x0250, "RTSO": 0x0231, "SO": 0x0233, "OE": 0x1237, "QSA": 0x0217, "FAULT": 0x0218}


def state_of(sw):
    """CiA 402 statusword decoding (bits 0-3, 5, 6)."""
    if sw & 0x4F == 0x40:
        return "SOD"
    if sw & 0x6F == 0x21:
        return "RTSO"
    if sw & 0x6F == 0x23:
        return "SO"
    if sw & 0x6F == 0x27:
        return "OE"
    if sw & 0x6F == 0x07:
        return "QSA"
    if sw & 0x4F == 0x08:
        return "FAULT"
    return "OTHER"


def connect(a):
    net = canopen.Network()
    net.connect(interface="udp_multicast", channel=a.group, port=a.port)
    return net


# ---------------------------------------------------------------- drive (LocalNode) role
class Drive:
    def __init__(self, net, node_id, eds, a):
        self.net, self.id, self.a = net, node_id, a
        self.node = canopen.LocalNode(node_id, eds)
        net.add_node(self.node)
        self.lock = threading.RLock()
        self.state = "SOD"
        self.mode = 0
        # Initial axis position: a few metres of cable in drive-io's scaling.
        self.pos = 30_000_000 + 1_000_000 * node_id
        self.pending = self.target = self.pos
        self.vel = 0
        self.cw = 0
        self.syncs = {}
        self.subscribed = []
        self.enabled_at = None
        self.muted = False
        self.consumer = None
        self.last_master_hb = None
        self.consumer_lost = False
        self.node.add_read_callback(self.on_read)
        self.node.add_write_callback(self.on_write)
        net.subscribe(0, self.on_nmt)
        net.subscribe(0x80, self.on_sync)

    def u32(self, index, sub):
        return struct.unpack("<I", self.node.get_data(index, sub))[0]

    def i16(self, index):
        return struct.unpack("<h", self.node.get_data(index, 0))[0]

    # -- object dictionary hooks (process data served live)
    def on_read(self, index, subindex, od):
        live = {0x6041: lambda: SW[self.state], 0x6064: lambda: self.pos, 0x606C: lambda: self.vel,
                0x2110: lambda: 1_000_000, 0x6061: lambda: self.mode, 0x6060: lambda: self.mode,
                0x607A: lambda: self.pending, 0x6040: lambda: self.cw}
        if subindex == 0 and index in live:
            return live[index]()
        if (index, subindex) == (0x1018, 2) and self.id == self.a.swap:
            return 0x00003000  # another product on this node id (firmware constant)
        return None

    def on_write(self, index, subindex, od, data):
        if index == 0x6060:
            if struct.unpack("<b", data)[0] != 8:
                raise SdoAbortedError(0x06090030)  # this drive does CSP only
            self.mode = 8
        elif index == 0x6040:
            self.controlword(struct.unpack("<H", data)[0])
        elif index == 0x1016 and subindex == 1:
            v = struct.unpack("<I", data)[0]
            self.set_consumer((v >> 16) & 0x7F, v & 0xFFFF)

    def set_consumer(self, producer, ms):
        if self.consumer:
            self.net.unsubscribe(0x700 + self.consumer[0], self.on_master_hb)
        self.consumer = (producer, ms) if producer and ms else None
        self.last_master_hb, self.consumer_lost = None, False
        if self.consumer:
            self.net.subscribe(0x700 + producer, self.on_master_hb)

    def on_master_hb(self, can_id, data, ts):
        self.last_master_hb = time.monotonic()
        self.consumer_lost = False

    # -- CiA 402 device control (transitions 2-16)
    def controlword(self, cw):
        with self.lock:
            prev, self.cw = self.cw, cw
            s = self.state
            shutdown = cw & 0x87 == 0x06
            switch_on = cw & 0x8F == 0x07
            enable = cw & 0x8F == 0x0F
            disable = cw & 0x82 == 0x00
            quick = cw & 0x86 == 0x02
            reset_edge = cw & 0x80 and not prev & 0x80
            if s == "SOD" and shutdown:
                s = "RTSO"
            elif s == "RTSO" and switch_on:
                s = "SO"
            elif s == "RTSO" and enable:
                s = "OE"
            elif s in ("RTSO", "SO") and (disable or quick):
                s = "SOD"
            elif s == "SO" and enable:
                s = "OE"
            elif s == "SO" and shutdown:
                s = "RTSO"
            elif s == "OE" and quick:
                s = "QSA"
            elif s == "OE" and switch_on:
                s = "SO"
            elif s == "OE" and shutdown:
                s = "RTSO"
            elif s == "OE" and disable:
                s = "SOD"
            elif s == "QSA" and disable:
                s = "SOD"
            elif s == "QSA" and enable:
                s = "OE"
            elif s == "FAULT" and reset_edge:
                s = "SOD"
            if s == "OE" and self.state != "OE":
                self.pending = self.target = self.pos  # never jump on enabling
                self.enabled_at = self.enabled_at or time.monotonic()
            self.state = s

    def abort_connection(self):
        """CiA 402 0x6007 reaction (NMT stopped, consumer heartbeat lost)."""
        code = self.i16(0x6007)
        with self.lock:
            if code == 1 and self.state != "FAULT":
                self.fault(0x8130)
            elif code == 2 and self.state in ("OE", "QSA", "SO", "RTSO"):
                self.state = "SOD"
            elif code == 3 and self.state == "OE":
                self.state = "QSA"

    def fault(self, code):
        self.state = "FAULT"
        self.node.emcy.send(code, 0x01)

    # -- NMT (python canopen's NmtSlave keeps the state; boot-up and resets are the firmware's)
    def on_nmt(self, can_id, data, ts):
        if len(data) != 2 or data[1] not in (0, self.id):
            return
        cmd = data[0]
        if cmd in (0x81, 0x82):
            self.reboot(communication_only=cmd == 0x82)
        elif cmd == 0x01:
            self.load_pdos()
        elif cmd == 0x02:
            self.abort_connection()

    def reboot(self, communication_only):
        with self.lock:
            for index in list(self.node.data_store):
                if not communication_only or 0x1000 <= index < 0x2000:
                    del self.node.data_store[index]
            for cob, cb in self.subscribed:
                self.net.unsubscribe(cob, cb)
            self.subscribed = []
            self.set_consumer(0, 0)
            if not communication_only:
                self.mode, self.state = 0, "SOD"
        self.net.send_message(0x700 + self.id, [0])  # boot-up
        self.node.nmt.send_command(0x80)  # -> pre-operational, heartbeat per 0x1017

    def load_pdos(self):
        """PDO configuration as the master wrote it into the object dictionary."""
        with self.lock:
            for cob, cb in self.subscribed:
                self.net.unsubscribe(cob, cb)
            self.subscribed = []
            self.node.rpdo.read(from_od=False)
            self.node.tpdo.read(from_od=False)
            for m in self.node.rpdo.map.values():
                if m.enabled:
                    self.subscribed.append((m.cob_id, m.on_message))
                    m.add_callback(self.on_rpdo)
            for m in self.node.tpdo.map.values():
                if m.enabled:
                    self.subscribed.append((m.cob_id, m.on_message))

    def on_rpdo(self, m):
        for var in m.map:
            if var.index == 0x6040:
                self.controlword(var.raw)
            elif var.index == 0x607A:
                self.pending = var.raw

    def on_sync(self, can_id, data, ts):
        if self.node.nmt.state != "OPERATIONAL":
            return
        with self.lock:
            lo = struct.unpack("<i", self.node.get_data(0x607D, 1))[0]
            hi = struct.unpack("<i", self.node.get_data(0x607D, 2))[0]
            self.target = min(max(self.pending, lo), hi)
            if self.state == "OE" and self.mode == 8:
                self.vel = (self.target - self.pos) * 1000  # ideal CSP axis, 1 ms period
                self.pos = self.target
            else:
                self.vel = 0
                if self.state == "QSA" and self.i16(0x605A) in (1, 2, 3, 4):
                    self.state = "SOD"
            maps = [m for m in self.node.tpdo.map.values() if m.enabled]
            for m in maps:
                tt = m.trans_type or 0
                if not 1 <= tt <= 240:
                    continue
                n = self.syncs.get(m.cob_id, 0) + 1
                self.syncs[m.cob_id] = 0 if n >= tt else n
                if n < tt:
                    continue
                for var in m.map:
                    var.raw = self.on_read(var.index, var.subindex, None)
                m.transmit()

    def poll(self):
        if self.consumer and self.last_master_hb and not self.consumer_lost:
            if time.monotonic() - self.last_master_hb > self.consumer[1] / 1000:
                self.consumer_lost = True
                self.node.emcy.send(0x8130, 0x11)
                self.abort_connection()
        a = self.a
        if self.id == a.node and self.enabled_at and time.monotonic() - self.enabled_at > a.after:
            if a.scenario == "emcy" and self.state != "FAULT":
                with self.lock:
                    self.fault(a.code)
            elif a.scenario == "heartbeat" and not self.muted:
                self.muted = True
                self.node.nmt.stop_heartbeat()
                self.node.nmt.on_write = lambda *args, **kw: None
            elif a.scenario == "reboot" and not self.muted:
                self.muted = True
                self.reboot(communication_only=False)


class Cell:
    """A CiA 404 measuring device (pulley load cell) as a python canopen LocalNode: SDO server,
    NMT slave and heartbeat are python canopen's; TPDOs are sent on SYNC as mapped."""

    def __init__(self, net, node_id, cable, eds):
        self.net, self.id = net, node_id
        self.node = canopen.LocalNode(node_id, eds)
        net.add_node(self.node)
        self.lock = threading.RLock()
        # The measured force in the process value's unit (0.1 N per 0x6131/0x6132).
        self.force_units = round((3000 + 100 * cable) * 10)
        self.syncs = {}
        self.subscribed = []
        self.node.add_read_callback(self.on_read)
        net.subscribe(0, self.on_nmt)
        net.subscribe(0x80, self.on_sync)

    def on_read(self, index, subindex, od):
        if index == 0x9130 and subindex == 1:
            return self.force_units
        return None

    def on_nmt(self, can_id, data, ts):
        if len(data) != 2 or data[1] not in (0, self.id):
            return
        if data[0] in (0x81, 0x82):
            with self.lock:
                for index in list(self.node.data_store):
                    if data[0] == 0x81 or 0x1000 <= index < 0x2000:
                        del self.node.data_store[index]
            self.net.send_message(0x700 + self.id, [0])  # boot-up
            self.node.nmt.send_command(0x80)
        elif data[0] == 0x01:
            with self.lock:
                self.node.tpdo.read(from_od=False)

    def on_sync(self, can_id, data, ts):
        if self.node.nmt.state != "OPERATIONAL":
            return
        with self.lock:
            for m in [m for m in self.node.tpdo.map.values() if m.enabled]:
                tt = m.trans_type or 0
                if not 1 <= tt <= 240:
                    continue
                n = self.syncs.get(m.cob_id, 0) + 1
                self.syncs[m.cob_id] = 0 if n >= tt else n
                if n < tt:
                    continue
                for var in m.map:
                    v = self.on_read(var.index, var.subindex, None)
                    if v is not None:
                        var.raw = v
                m.transmit()


def run_drives(a):
    net = connect(a)
    drives = [Drive(net, n, a.eds, a) for n in range(1, a.drives + 1)]
    cells = [Cell(net, 32 + n, n, a.cell_eds) for n in range(1, a.drives + 1)] if a.cells else []
    for d in drives + cells:
        d.net.send_message(0x700 + d.id, [0])  # power-on boot-up
        d.node.nmt.send_command(0x80)
    print(f"python canopen {canopen.__version__}: {len(drives)} LocalNode drives from {a.eds}"
          f"{f', {len(cells)} CiA 404 load cells from {a.cell_eds}' if cells else ''}", flush=True)
    t_end = time.monotonic() + a.seconds
    while time.monotonic() < t_end:
        for d in drives:
            d.poll()
        time.sleep(0.002)
    net.disconnect()
    return 0


# ---------------------------------------------------------------- master (RemoteNode) role
class Checks:
    def __init__(self):
        self.failed = 0

    def __call__(self, ok, what):
        print(f"  {'ok  ' if ok else 'FAIL'} {what}", flush=True)
        self.failed += 0 if ok else 1


def run_master(a):
    check = Checks()
    net = connect(a)
    hb = net.send_periodic(0x77F, [0x05], 0.01)  # this master's heartbeat, node 0x7F
    nodes = [net.add_node(n, a.eds) for n in range(1, a.drives + 1)]
    booted = set()
    for n in nodes:
        net.subscribe(0x700 + n.id, lambda cob, data, ts: data[:1] == b"\x00" and booted.add(cob - 0x700))
    net.nmt.send_command(0x82)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5 and len(booted) < len(nodes):
        time.sleep(0.01)
    check(booted == {n.id for n in nodes}, f"boot-up of nodes {sorted(booted)} after NMT reset communication")
    for n in nodes:
        check(n.sdo[0x1000].raw == 0x00020192, f"node {n.id}: 0x1000 device type CiA 402 servo")
        n.sdo[0x1017].raw = 20
        n.sdo[0x6007].raw = 3          # connection loss => quick stop
        n.sdo[0x605A].raw = 6          # stay in quick stop active
        n.sdo[0x1016][1].raw = (0x7F << 16) | 100
        n.sdo[0x6060].raw = 8
        check(n.sdo[0x6061].raw == 8, f"node {n.id}: 0x6061 reads CSP after 0x6060 = 8")
        check(n.sdo[0x1016][1].raw == (0x7F << 16) | 100, f"node {n.id}: 0x1016 reads back")
        for what, fn, code in [
            ("0x6060 = 1 (not CSP)", lambda: setattr(n.sdo[0x6060], "raw", 1), 0x06090030),
            ("0x6041 (read-only)", lambda: setattr(n.sdo[0x6041], "raw", 0), 0x06010002),
            ("0x6007 = 7 (above HighLimit)", lambda: setattr(n.sdo[0x6007], "raw", 7), 0x06090031),
            ("upload 0x2FFF (no object)", lambda: n.sdo.upload(0x2FFF, 0), 0x06020000),
        ]:
            try:
                fn()
                check(False, f"node {n.id}: {what} accepted")
            except SdoAbortedError as e:
                check(e.code == code, f"node {n.id}: {what} aborted 0x{e.code:08X} (want 0x{code:08X})")
        # python canopen's own PDO layout, different from drive-io's (order and COB-IDs).
        n.tpdo.read()
        n.rpdo.read()
        n.tpdo[1].clear()
        n.tpdo[1].add_variable(0x6064)
        n.tpdo[1].add_variable(0x6041)
        n.tpdo[1].cob_id = 0x190 + n.id
        n.tpdo[1].trans_type = 1
        n.tpdo[1].enabled = True
        n.tpdo[2].clear()
        n.tpdo[2].add_variable(0x606C)
        n.tpdo[2].trans_type = 1
        n.tpdo[2].enabled = True
        n.rpdo[1].clear()
        n.rpdo[1].add_variable(0x607A)
        n.rpdo[1].add_variable(0x6040)
        n.rpdo[1].cob_id = 0x210 + n.id
        n.rpdo[1].trans_type = 1
        n.rpdo[1].enabled = True
        n.tpdo.save()
        n.rpdo.save()
        check(n.sdo[0x1A00][1].raw == 0x60640020, f"node {n.id}: TPDO1 remapped (position first)")
    net.nmt.send_command(0x01)
    for n in nodes:
        n.nmt.wait_for_heartbeat(2)
        check(n.nmt.state == "OPERATIONAL", f"node {n.id}: heartbeat says OPERATIONAL")

    def cycle(cw_of, target_of, k=1):
        for _ in range(k):
            for n in nodes if cw_of else []:
                n.rpdo[1]["Target position"].raw = target_of(n)
                n.rpdo[1]["Controlword"].raw = cw_of(n)
                n.rpdo[1].transmit()
            time.sleep(0.0005)
            net.sync.transmit()
            time.sleep(0.002)

    def sw(n):
        return n.tpdo[1]["Statusword"].raw

    def pos(n):
        return n.tpdo[1]["Position actual value"].raw

    enable = {"SOD": 0x06, "RTSO": 0x07, "SO": 0x0F, "OE": 0x0F, "FAULT": 0x80, "QSA": 0x0F}
    cycle(lambda n: 0, lambda n: 0, 3)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5 and not all(state_of(sw(n)) == "OE" for n in nodes):
        cycle(lambda n: enable.get(state_of(sw(n)), 0), pos)
    check(all(state_of(sw(n)) == "OE" for n in nodes), "CiA 402 enable through the remapped PDOs")
    start = {n.id: pos(n) for n in nodes}
    goal = {n.id: start[n.id] + 20_000 for n in nodes}
    for k in range(1, 201):
        cycle(lambda n: 0x0F, lambda n: start[n.id] + 100 * k)
    cycle(lambda n: 0x0F, lambda n: goal[n.id], 100)
    for n in nodes:
        check(abs(pos(n) - goal[n.id]) <= 2, f"node {n.id}: followed 20000 counts, at {pos(n) - start[n.id]}")
    # Quick stop: acknowledged in the statusword, velocity 0.
    t0 = time.monotonic()
    while time.monotonic() - t0 < 2:
        cycle(lambda n: 0x02, lambda n: goal[n.id])
        if all(state_of(sw(n)) == "QSA" and n.tpdo[2]["Velocity actual value"].raw == 0 for n in nodes):
            break
    check(all(state_of(sw(n)) == "QSA" for n in nodes), "quick stop acknowledged (Quick Stop Active)")
    check(all(n.tpdo[2]["Velocity actual value"].raw == 0 for n in nodes), "velocity actual 0 after quick stop")
    # EMCY: a following error (0x6065/0x6066 set by SDO in operational) faults the drive.
    victim = nodes[0]
    victim.sdo[0x6065].raw = 100
    victim.sdo[0x6066].raw = 2
    cycle(lambda n: 0x0F, lambda n: goal[n.id], 5)  # transition 16: back to Operation Enabled
    victim.emcy.reset()
    cycle(lambda n: 0x0F, lambda n: goal[n.id] + (1_000_000 if n is victim else 0), 20)
    codes = [e.code for e in victim.emcy.log]
    check(0x8611 in codes, f"EMCY 0x8611 (following error) from node {victim.id}: {[hex(c) for c in codes]}")
    check(state_of(sw(victim)) == "FAULT", f"node {victim.id}: statusword Fault")
    # Heartbeat loss at the drives: this master falls silent => EMCY 0x8130, 0x6007 = 3 quick stop.
    cycle(lambda n: 0x80 if state_of(sw(n)) == "FAULT" else 0x0F, lambda n: pos(n), 3)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 3 and not all(state_of(sw(n)) == "OE" for n in nodes):
        cycle(lambda n: enable.get(state_of(sw(n)), 0), pos)
    check(all(state_of(sw(n)) == "OE" for n in nodes), "fault reset and re-enable")
    for n in nodes:
        n.emcy.reset()
    hb.stop()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 1:
        cycle(None, None)  # a dead master: no RPDOs; SYNC only, to read the TPDOs
    for n in nodes:
        codes = [e.code for e in n.emcy.log]
        check(0x8130 in codes, f"node {n.id}: EMCY 0x8130 (heartbeat) after the master's heartbeat stopped")
        check(state_of(sw(n)) == "QSA", f"node {n.id}: 0x6007 = 3 => Quick Stop Active")
    net.nmt.send_command(0x02)
    net.disconnect()
    return 1 if check.failed else 0


# ---------------------------------------------------------------- DCF check
def check_dcf(a):
    check = Checks()
    cpm = 10 * 1048576 / (math.pi * 0.305)  # drive-io-interop's scaling, counts per metre
    for n in range(1, a.drives + 1):
        path = f"{a.dcf_dir}/node{n:02}.dcf"
        od = canopen.import_od(path, n)
        if a.vendor:
            check(od[0x1A01][1].value == 0x606C0020 and od[0x1A01][0].value == 1,
                  f"{path}: TPDO2 = velocity actual alone (no force object)")
            check(od[0x1801][2].value == 10, f"{path}: TPDO2 every 10th SYNC")
            check(od[0x1401][1].value & 0x80000000 != 0, f"{path}: stray RPDO2 disabled")
            check(od[0x2000].value == f"CRS winch {n} (cable {n})", f"{path}: 0x2000 = {od[0x2000].value!r}")
        else:
            check(od[0x1A01][2].value == 0x21100020, f"{path}: TPDO2 entry 2 = 0x2110 (ParameterValue)")
        check(od[0x1800][1].value == 0x180 + n, f"{path}: TPDO1 COB-ID 0x{0x180 + n:X}")
        check(od[0x6060].value == 8 and od[0x6007].value == 2, f"{path}: 0x6060 = 8, 0x6007 = 2")
        check(od[0x60C2][2].value == -3, f"{path}: 0x60C2sub2 = {od[0x60C2][2].value} (-3: ms)")
        sign, offset = (1, 0) if n % 2 == 1 else (-1, 200_000_000)
        ends = [offset, offset + sign * 30.0 * cpm]
        lo = round(min(ends))
        check(abs(od[0x607D][1].value - lo) <= 1, f"{path}: 0x607Dsub1 = {od[0x607D][1].value} (signed, want {lo})")
        check(od.node_id == n, f"{path}: [DeviceComissioning] NodeID {n}")
    for n in range(33, 33 + a.drives) if a.vendor else []:
        path = f"{a.dcf_dir}/node{n:02}.dcf"
        od = canopen.import_od(path, n)
        check(od[0x1A00][1].value == 0x91300120, f"{path}: load cell TPDO1 = 0x9130sub1")
        check(od[0x1017].value == 20, f"{path}: heartbeat 20 ms")
    return 1 if check.failed else 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("role", choices=["drive", "master", "dcf"])
    p.add_argument("--group", default="239.74.163.2")
    p.add_argument("--port", type=int, default=43113)
    p.add_argument("--eds", default="config/eds/crs-winch.eds")
    p.add_argument("--drives", type=int, default=2)
    p.add_argument("--scenario", default="run")
    p.add_argument("--node", type=int, default=2)
    p.add_argument("--code", type=lambda s: int(s, 0), default=0x2310)
    p.add_argument("--after", type=float, default=0.5)
    p.add_argument("--seconds", type=float, default=20)
    p.add_argument("--dcf-dir")
    p.add_argument("--cells", action="store_true")
    p.add_argument("--cell-eds", default="config/eds/crs-load-cell.eds")
    p.add_argument("--swap", type=int, default=0)
    p.add_argument("--vendor", action="store_true")
    a = p.parse_args()
    return {"drive": run_drives, "master": run_master, "dcf": check_dcf}[a.role](a)


if __name__ == "__main__":
    sys.exit(main())
