#!/usr/bin/env python3
"""An independent device under test: a minimal four-position north-finder.

Written against the wire contract only: python-can on a SocketCAN interface, cantools reading
wire/bench.dbc for every frame it decodes and encodes, and the IMU's pulse weight and rate from
the nav.toml the bench writes (its calibration binding). No code of the bench is imported.

It commands the turntable over CAN (Enable, Unlock, IndexAbs to 0/90/180/270, Lock, with a
10 Hz heartbeat), fits each dwell's gyro counters by least squares (the dither averages out),
takes the heading from the four positions' horizontal rates, and sends NAV_TIME at 50 Hz of IMU
samples, with NAV_ATT (its relative heading from the z gyro while it indexes, the found heading
after) and NAV_HGT (its heading sigma).

Faults on purpose, for the bench to catch:
  --delay S        every solution goes out S seconds late (its time tags stay honest);
  --stamp-early S  every solution names the sample S seconds before the one its data reach;
  --stray S        a frame outside the DBC (identifier 0x3FF) every S seconds;
  --backwards      one NAV_TIME, 30 s in, names a sample 1000 before the one before it;
  --drift-ppm P    its clock runs P ppm fast against the IMU's: the sample it names runs ahead
                   of the one its data reach by P ppm of the time since its first (a device
                   that counts time on its own crystal, or with a mis-set sample rate);
  --stale S        its data are S seconds older than its tags: the solution of sample k is
                   named k + S * rate and sent when that sample has come (a device that stamps
                   with the newest sample, not the one its solution is of).

On a lab's own contract (--mapping FILE, the bench's mapping of that DBC: docs/your-dbc.md)
it reads the IMU's blocks of rates (CAN FD, 29-bit identifiers) and the table's reports by the
mapping's names, checks every frame's alive counter and checksum, commands the table by the
lab's opcodes and sends its solution where the mapping's [solution] says, protected as the
mapping says. On SIGTERM it prints what it received and how many of those frames failed their
checks. Two more faults on purpose there:
  --bad-crc N      every Nth solution frame goes out with its checksum wrong;
  --skip-alive N   every Nth solution frame's alive counter skips one.
"""

import argparse
import collections
import math
import operator
import select
import signal
import socket
import struct
import sys
import time
import tomllib

import can
import cantools

OMEGA = 7.2921151467e-5  # earth rate, rad/s
HEADER = struct.Struct("=IB")  # a SocketCAN frame's identifier and data length


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iface", required=True)
    ap.add_argument("--dbc", required=True)
    ap.add_argument("--config", required=True, help="the nav.toml the bench wrote")
    ap.add_argument("--dwell", type=float, default=15.0)
    ap.add_argument("--delay", type=float, default=0.0)
    ap.add_argument("--stamp-early", type=float, default=0.0)
    ap.add_argument("--stray", type=float, default=0.0)
    ap.add_argument("--backwards", action="store_true")
    ap.add_argument("--drift-ppm", type=float, default=0.0)
    ap.add_argument("--stale", type=float, default=0.0)
    ap.add_argument("--mapping", help="a lab's mapping of --dbc (its own contract)")
    ap.add_argument("--bad-crc", type=int, default=0)
    ap.add_argument("--skip-alive", type=int, default=0)
    a = ap.parse_args()
    if a.mapping:
        LabNorthFinder(a, tomllib.load(open(a.mapping, "rb"))).run()
        return
    cfg = tomllib.load(open(a.config, "rb"))
    imu = cfg.get("imu", {})
    pulse = imu.get("gyro_pulse_arcsec", [1.0, 1.0, 1.0])
    rate_hz = imu.get("rate_hz", 2000.0)
    NorthFinder(a, pulse, rate_hz).run()


class NorthFinder:
    def __init__(self, a, pulse, rate_hz):
        self.a = a
        self.db = cantools.database.load_file(a.dbc)
        m = self.db.get_message_by_name
        self.gyro, self.status = m("IMU_GYRO"), m("TT_STATUS")
        self.cmd, self.ack = m("TT_CMD"), m("TT_ACK")
        self.nav_time, self.nav_att, self.nav_hgt = m("NAV_TIME"), m("NAV_ATT"), m("NAV_HGT")
        # python-can sends (commands, the solution); the 2 kHz stream is read in bulk from a
        # raw SocketCAN socket: python-can's message object per frame costs about 80 us in an
        # emulated guest, more than the stream leaves
        self.bus = can.Bus(
            interface="socketcan",
            channel=a.iface,
            can_filters=[{"can_id": 0x7FF, "can_mask": 0x7FF}],
        )
        ids = [self.gyro.frame_id, self.status.frame_id, self.ack.frame_id]
        self.rx = open_rx(a.iface, [(i, 0x7FF) for i in ids], fd=False)
        # the 2 kHz gyro frame's counters in one step from the received bytes (x, y, z, the
        # sample counter), and the identifiers as plain numbers: at 2 kHz in an emulated
        # guest every attribute lookup and object per frame shows
        self.gyro_counts = counters(
            self.gyro, ("GyroX_Count", "GyroY_Count", "GyroZ_Count", "SampleCounter")
        )
        self.gyro_id, self.status_id, self.ack_id = ids
        self.pulse_rad = [p * math.pi / (180 * 3600) for p in pulse]
        self.rate_hz = rate_hz
        # a classic frame's 16 bytes, 11-bit identifiers, housekeeping every 20 frames (2 kHz)
        self.frame_size, self.id_mask, self.housekeep_every = 16, 0x7FF, 20
        self.nav_seq = 0
        self.raw = None
        self.start_state()

    def start_state(self):
        self.seq = 0
        self.last_hb = 0.0
        self.table = None  # (state, angle)
        self.count = None  # unwrapped [x, y, z] pulses (or angles), sample count
        self.sample = None
        self.fit = None  # least-squares sums of the dwell, in chunks
        self.heading = None
        self.sigma = 6.5
        self.mode = self.mode_of("NorthFinding")
        self.out = collections.deque()
        self.stale = collections.deque()  # (the sample it waits for, frames)
        self.last_stray = time.monotonic()
        self.first_sample = None

    def mode_of(self, name):
        return {"NorthFinding": 2, "Navigation": 3}[name]

    # ---- the bus ----
    def send(self, msg, **signals):
        data = msg.encode(signals, strict=False)
        self.bus.send(can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=False))

    def command(self, name, arg=0.0):
        self.seq = (self.seq + 1) % 256
        code = self.cmd.get_signal_by_name("Command").choices
        number = next(k for k, v in code.items() if str(v) == name)
        self.send(self.cmd, Seq=self.seq, Command=number, Axis=0, Arg=arg)

    def poll(self, timeout=0.01):
        """Take the frames waiting (a few at a time), heartbeat, send what is due."""
        select.select([self.rx], [], [], timeout)
        n = 0
        while True:
            try:
                f = self.rx.recv(self.frame_size)
            except BlockingIOError:
                break
            can_id, dlc = HEADER.unpack_from(f)
            self.take(can_id & self.id_mask, f, dlc)
            n += 1
            if n % self.housekeep_every == 0:
                self.housekeeping()
        self.housekeeping()

    def housekeeping(self):
        now = time.monotonic()
        if self.a.stray > 0 and now - self.last_stray >= self.a.stray:
            self.last_stray = now
            self.bus.send(can.Message(arbitration_id=0x3FF, data=b"\x00" * 8, is_extended_id=False))
        if now - self.last_hb >= 0.1:
            self.last_hb = now
            self.command("Heartbeat")
        while self.out and self.out[0][0] <= now:
            for m, s in self.out.popleft()[1]:
                self.send(m, **s)

    def take(self, can_id, f, dlc):
        """One received frame: `f` as the socket gave it, its data from byte 8, `dlc` long."""
        if can_id == self.gyro_id:
            raw = self.gyro_counts(f, dlc)
            old = self.raw
            if old is None:
                self.count = [0, 0, 0, raw[3]]
            else:
                c = self.count
                # each 16-bit counter unwrapped: the step since the last frame, -32768..32767
                c[0] += (raw[0] - old[0] + 32768) % 65536 - 32768
                c[1] += (raw[1] - old[1] + 32768) % 65536 - 32768
                c[2] += (raw[2] - old[2] + 32768) % 65536 - 32768
                c[3] += (raw[3] - old[3] + 32768) % 65536 - 32768
            self.raw = raw
            self.sample = sample = self.count[3]
            if self.fit is not None:
                self.fit.add(sample, self.count[0], self.count[1])
            if sample % 40 == 0:
                self.solution()
            while self.stale and self.stale[0][0] <= sample:
                self.out.append((time.monotonic() + self.a.delay, self.stale.popleft()[1]))
            return
        data = f[8 : 8 + dlc]
        if can_id == self.status_id:
            d = self.status.decode(data, decode_choices=False)
            if d["Axis"] == 0:
                self.table = (int(d["State"]), float(d["Angle"]))
        elif can_id == self.ack_id:
            d = self.ack.decode(data, decode_choices=False)
            if d["Result"] != 0 and d["Command"] != 0:
                sys.exit(f"northfinder: the table refused command {d['Command']}: result {d['Result']}")

    def solution(self):
        if self.first_sample is None:
            self.first_sample = self.sample
        since = self.sample - self.first_sample
        stale = round(self.a.stale * self.rate_hz)
        named = (self.sample + stale + round(since * self.a.drift_ppm * 1e-6)
                 - round(self.a.stamp_early * self.rate_hz))
        if self.a.backwards and self.sample - self.first_sample == round(30 * self.rate_hz):
            named -= 1000 + 40
        if self.heading is None:
            # while indexing: the heading relative to the start, from the z gyro
            h = -math.degrees(self.count[2] * self.pulse_rad[2])
        else:
            h = self.heading
        frames = self.frames(named, h)
        if stale > 0:
            self.stale.append((self.sample + stale, frames))
        else:
            self.out.append((time.monotonic() + self.a.delay, frames))

    def frames(self, named, h):
        """The solution's frames: (message, signals) pairs."""
        s = self.nav_seq
        self.nav_seq = (s + 1) % 256
        return [
            (self.nav_time, dict(SampleCount=named % 2**32, Seq=s, Mode=self.mode,
                                 HealthImuTimeout=0, HealthImuGaps=0, HealthImuBit=0,
                                 HealthGpsStale=0, HealthTurntable=0, HealthFilter=0,
                                 GpsRxBytes=0, HealthGpsData=0, HealthCanBus=0)),
            (self.nav_att, dict(Seq=s, Heading=h % 360.0, Pitch=0.0, Roll=0.0)),
            (self.nav_hgt, dict(Seq=s, Height=0.0, PosSigma=655.35, HeadingSigma=min(self.sigma, 6.5))),
        ]

    # ---- the procedure ----
    def wait(self, what, cond, limit=60.0):
        t0 = time.monotonic()
        while not cond():
            if time.monotonic() - t0 > limit:
                sys.exit(f"northfinder: no {what} within {limit} s (table {self.table})")
            self.poll()

    def run_for(self, seconds):
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            self.poll()

    def index(self, angle):
        self.command("Unlock")
        self.wait("unlocked table", lambda: self.table is not None and self.table[0] == 1)
        self.command("IndexAbs", angle)
        self.run_for(0.1)
        near = lambda: abs((self.table[1] - angle + 180.0) % 360.0 - 180.0) < 0.01
        self.wait(f"table at {angle} deg", lambda: self.table[0] == 1 and near())

        self.command("Lock")
        self.wait("locked table", lambda: self.table[0] == 4)

    def run(self):
        self.wait("IMU stream", lambda: self.sample is not None and self.table is not None)

        self.command("Enable")
        self.run_for(0.2)
        rates = []
        for angle in (0.0, 90.0, 180.0, 270.0):
            self.index(angle)
            self.run_for(1.0)  # settle
            self.fit = Fit(self.a.dwell * self.rate_hz / 10)
            self.run_for(self.a.dwell)
            rates.append(self.fit.rates(self.rate_hz, self.pulse_rad))
            self.fit = None
            (x, y), (sx, sy) = rates[-1]
            dph = math.degrees(1) * 3600
            print(f"northfinder: at {angle:.0f} deg: x {x * dph:+.4f} y {y * dph:+.4f} deg/h "
                  f"(sigma {sx * dph:.4f}, {sy * dph:.4f})", flush=True)
        self.index(0.0)
        (x0, y0), (x90, y90), (x180, y180), (x270, y270) = [r[0] for r in rates]
        # level body, y forward: at the IMU's heading p, wx = -W sin p, wy = W cos p; the table
        # at angle a turns the IMU's heading to (heading - a)
        s = (-x0 + x180 + y90 - y270) / 4.0
        c = (y0 - y180 + x90 - x270) / 4.0
        self.heading = math.degrees(math.atan2(s, c)) % 360.0
        var = sum(r[1][i] ** 2 for r, i in zip(rates, (0, 1, 0, 1))) / 16.0
        w = math.hypot(s, c)
        # the simple method's sigma: the dwells' noise, and a floor for what it leaves out: it
        # has no accelerometers and takes the IMU as level, so a tilt of up to 0.3 deg lets
        # the vertical earth rate (7 deg/h here) into the horizontal ones by up to 0.04 deg/h,
        # 0.15 deg of heading
        self.sigma = math.hypot(math.degrees(math.sqrt(var) / w), 0.15)
        self.mode = self.mode_of("Navigation")  # the heading is known
        print(f"northfinder: heading {self.heading:.4f} deg, sigma {self.sigma:.4f} deg, "
              f"earth rate {math.degrees(w) * 3600:.3f} deg/h", flush=True)
        while True:
            self.poll()


def open_rx(iface, filters, fd):
    """A raw SocketCAN socket on `iface` hearing the (identifier, mask) `filters`, CAN FD frames
    too where `fd`, non-blocking."""
    rx = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    if fd:
        rx.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
    rx.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER,
                  b"".join(struct.pack("=II", i, m) for i, m in filters))
    # room for seconds of the stream when the interpreter stalls (SO_RCVBUFFORCE, 33, passes
    # the system's limit where we may)
    try:
        rx.setsockopt(socket.SOL_SOCKET, 33, 4 << 20)
    except OSError:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    rx.bind((iface,))
    rx.setblocking(False)
    return rx


# Checksums by the names the bench's mapping uses: width, polynomial, initial value, reflected
# in and out, final xor.
CRCS = {
    "CRC-8/SAE-J1850": (8, 0x1D, 0xFF, False, 0xFF),
    "CRC-8/AUTOSAR": (8, 0x2F, 0xFF, False, 0xFF),
    "CRC-8/SMBUS": (8, 0x07, 0x00, False, 0x00),
    "CRC-16/IBM-3740": (16, 0x1021, 0xFFFF, False, 0x0000),
    "CRC-16/ARC": (16, 0x8005, 0x0000, True, 0x0000),
}


def crc(name, data):
    width, poly, value, reflected, xorout = CRCS[name]
    top, mask = 1 << (width - 1), (1 << width) - 1
    if reflected:
        rpoly = int(f"{poly:0{width}b}"[::-1], 2)
        for b in data:
            value ^= b
            for _ in range(8):
                value = (value >> 1) ^ rpoly if value & 1 else value >> 1
    else:
        for b in data:
            value ^= b << (width - 8)
            for _ in range(8):
                value = ((value << 1) ^ poly) & mask if value & top else (value << 1) & mask
    return value ^ xorout


class Protection:
    """A message's alive counter and checksum as the mapping's [[protect]] says: filled in on
    the frames sent, checked on the frames received."""

    def __init__(self, msg, p):
        self.msg, self.p = msg, p
        self.alive_sig = msg.get_signal_by_name(p["alive"]) if p.get("alive") else None
        self.crc_sig = msg.get_signal_by_name(p["crc"]) if p.get("crc") else None
        first, last = p.get("bytes", [1, msg.length - 1])
        self.span = slice(first, last + 1)
        self.sent = 0
        self.last = None
        self.bad_crc = self.skips = self.checked = 0

    def wrap(self, sig):
        return 1 << sig.length

    def fill(self, signals, corrupt=False, skip=False):
        """The frame's bytes from `signals`, alive counter and checksum filled in."""
        if self.alive_sig is not None:
            self.sent += 1 + (1 if skip else 0)
            signals[self.alive_sig.name] = (self.sent - 1) % self.wrap(self.alive_sig)
        if self.crc_sig is not None:
            signals[self.crc_sig.name] = 0
        data = bytearray(self.msg.encode(signals, strict=False))
        if self.crc_sig is not None:
            c = crc(self.p["algorithm"], data[self.span]) ^ (0x5A if corrupt else 0)
            signals[self.crc_sig.name] = c
            data = bytearray(self.msg.encode(signals, strict=False))
        return bytes(data)

    def check(self, data, decoded):
        self.checked += 1
        if self.crc_sig is not None:
            if decoded[self.crc_sig.name] != crc(self.p["algorithm"], data[self.span]):
                self.bad_crc += 1
        if self.alive_sig is not None:
            a = decoded[self.alive_sig.name]
            if self.last is not None and a != (self.last + 1) % self.wrap(self.alive_sig):
                self.skips += 1
            self.last = a


class LabNorthFinder(NorthFinder):
    """The same drill on a lab's own contract, by its DBC and the bench's mapping of it."""

    def __init__(self, a, mapping):
        self.a = a
        self.db = cantools.database.load_file(a.dbc, strict=False)
        m = self.db.get_message_by_name
        imu, tt, sol = mapping["imu"], mapping["turntable"], mapping["solution"]
        self.gyro_map, self.tt_map, self.sol_map = imu["gyro"], tt, sol
        self.gyro, self.report, self.cmd = m(imu["gyro"]["message"]), m(tt["report"]), m(tt["command"])
        self.heading_msg = m(sol["message"])
        self.protect = {p["message"]: Protection(m(p["message"]), p) for p in mapping.get("protect", [])}
        self.per_frame = imu.get("samples_per_frame", 1)
        self.state_of = {v: k for k, v in tt["states"].items()}
        self.ours = {"Disabled": 0, "Idle": 1, "Moving": 2, "Settling": 3, "Locked": 4, "Fault": 5}
        self.modes = sol["modes"]
        self.bus = can.Bus(interface="socketcan", channel=a.iface, fd=True,
                           can_filters=[{"can_id": 0, "can_mask": 0xFFFFFFFF, "extended": True}])
        eff = socket.CAN_EFF_FLAG
        ids = [self.gyro.frame_id, self.report.frame_id]
        self.rx = open_rx(a.iface, [(i | eff, socket.CAN_EFF_MASK | eff) for i in ids], fd=True)
        self.gyro_id, self.report_id = ids
        self.signals = [[n.replace("{k}", str(k)) for n in self.gyro_map["signals"]]
                        for k in range(self.per_frame)]
        self.rate_hz = imu["rate_hz"]
        self.pulse_rad = [1.0, 1.0, 1.0]  # the counts are angles, rad
        # CAN FD frames of 72 bytes, 29-bit identifiers, blocks of ten samples
        self.frame_size, self.id_mask, self.housekeep_every = 72, socket.CAN_EFF_MASK, 5
        self.ctr = None
        self.solutions = 0
        self.start_state()
        signal.signal(signal.SIGTERM, self.summary)

    def mode_of(self, name):
        return self.modes[name]

    def summary(self, *_):
        for name, p in sorted(self.protect.items()):
            if p.checked:
                print(f"northfinder: received {p.checked} {name}: {p.bad_crc} bad checksums, "
                      f"{p.skips} alive counter skips", flush=True)
        sys.exit(0)

    def send(self, msg, **signals):
        p = self.protect.get(msg.name)
        if msg is self.heading_msg:
            self.solutions += 1
        n = self.solutions if msg is self.heading_msg else 0
        if p is not None:
            data = p.fill(signals, corrupt=n > 0 and self.a.bad_crc > 0 and n % self.a.bad_crc == 0,
                          skip=n > 0 and self.a.skip_alive > 0 and n % self.a.skip_alive == 0)
        else:
            data = msg.encode(signals, strict=False)
        self.bus.send(can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=True,
                                  is_fd=len(data) > 8, bitrate_switch=len(data) > 8))

    def command(self, name, arg=0.0):
        t = self.tt_map
        self.seq = (self.seq + 1) % 256
        signals = {t["opcode"]: t["opcodes"][name]}
        if t.get("sequence"):
            signals[t["sequence"]] = self.seq
        if t.get("argument"):
            signals[t["argument"]] = arg
        self.send(self.cmd, **signals)

    def take(self, can_id, f, dlc):
        data = f[8 : 8 + dlc]
        if can_id == self.report_id:
            d = self.report.decode(data, decode_choices=False)
            if self.report.name in self.protect:
                self.protect[self.report.name].check(data, d)
            state = self.ours.get(self.state_of.get(int(d[self.tt_map["state"]])), 5)
            self.table = (state, float(d[self.tt_map["angle"]]) % 360.0)
            return
        if can_id != self.gyro_id:
            return
        d = self.gyro.decode(data, decode_choices=False)
        if self.gyro.name in self.protect:
            self.protect[self.gyro.name].check(data, d)
        ctr_sig = self.gyro.get_signal_by_name(self.gyro_map["counter"])
        ctr, wrap = int(d[ctr_sig.name]), 1 << ctr_sig.length
        if self.ctr is None:
            self.count = [0.0, 0.0, 0.0, ctr]
        else:
            self.count[3] += (ctr - self.ctr) % wrap
        self.ctr = ctr
        dt = math.radians(1.0) / self.rate_hz  # deg/s over a sample, in rad
        for k, names in enumerate(self.signals):
            c = self.count
            c[0] += d[names[0]] * dt
            c[1] += d[names[1]] * dt
            c[2] += d[names[2]] * dt
            self.sample = sample = c[3] + k
            if self.fit is not None:
                self.fit.add(sample, c[0], c[1])
            if sample % 20 == 19:
                self.solution()
            while self.stale and self.stale[0][0] <= sample:
                self.out.append((time.monotonic() + self.a.delay, self.stale.popleft()[1]))

    def frames(self, named, h):
        s = self.sol_map
        signals = {s["time_tag"]: named % (1 << self.heading_msg.get_signal_by_name(s["time_tag"]).length),
                   s["mode"]: self.mode}
        if s.get("heading"):
            signals[s["heading"]] = h % 360.0
        if s.get("heading_sigma"):
            signals[s["heading_sigma"]] = min(self.sigma, 6.5)
        return [(self.heading_msg, signals)]


def counters(msg, names):
    """A fast reader of `msg`'s raw signals `names`, from its layout in the DBC: when every
    signal is a little-endian unsigned field of 8, 16 or 32 bits on a byte boundary, one
    struct.unpack_from at the data's offset (byte 8 of a SocketCAN frame); else cantools' own
    decode. Called with the frame as received and its data length; returns the values in the
    order of `names`."""
    sigs = sorted(msg.signals, key=lambda s: s.start)
    fmt, at = "<", 0
    for s in sigs:
        code = {8: "B", 16: "H", 32: "I"}.get(s.length)
        if s.byte_order != "little_endian" or s.is_signed or code is None or s.start != at:
            def decode(f, dlc):
                d = msg.decode(f[8 : 8 + dlc], decode_choices=False, scaling=False)
                return tuple(d[n] for n in names)

            return decode
        fmt += code
        at += s.length
    order = [s.name for s in sigs]
    pick = operator.itemgetter(*(order.index(n) for n in names))
    unpack = struct.Struct(fmt).unpack_from
    size = at // 8

    def read(f, dlc):
        if dlc < size:
            raise ValueError(f"{msg.name}: {dlc} data bytes, its layout needs {size}")
        return pick(unpack(f, 8))

    return read


class Fit:
    """Least-squares slopes of the x and y gyro counters over a whole dwell: the dither (a few
    hundred arcsec at 300-430 Hz) leaves the slope over 10 s almost untouched, where it would
    spoil the slope of a short window. The sigma comes from the residuals' chunk means (the
    dither averages out inside each chunk): the slope's standard error for points spread over
    the dwell."""

    def __init__(self, chunk):
        self.chunk = max(int(chunk), 10)
        self.k0 = None
        self.s = [0.0] * 7  # n, su, suu, sx, sux, sy, suy
        self.chunks = []  # [n, su, sx, sy]

    def add(self, k, x, y):
        if self.k0 is None:
            self.k0 = (k, x, y)
        u, x, y = k - self.k0[0], x - self.k0[1], y - self.k0[2]
        s = self.s
        s[0] += 1
        s[1] += u
        s[2] += u * u
        s[3] += x
        s[4] += u * x
        s[5] += y
        s[6] += u * y
        if not self.chunks or self.chunks[-1][0] >= self.chunk:
            self.chunks.append([0, 0.0, 0.0, 0.0])
        c = self.chunks[-1]
        c[0] += 1
        c[1] += u
        c[2] += x
        c[3] += y

    def rates(self, rate_hz, pulse_rad):
        """Mean (x, y) rate, rad/s, and their sigmas."""
        n, su, suu, sx, sux, sy, suy = self.s
        den = n * suu - su * su
        out, sig = [], []
        for i, (sv, suv) in enumerate(((sx, sux), (sy, suy))):
            b = (n * suv - su * sv) / den
            a = (sv - b * su) / n
            # a short last chunk's mean is the dither's, not the noise's
            full = [c for c in self.chunks if c[0] >= self.chunk // 2]
            res = [c[2 + i] / c[0] - (a + b * c[1] / c[0]) for c in full]
            m = len(res)
            sd = math.sqrt(sum(r * r for r in res) / max(m - 2, 1))
            span = n  # samples the dwell spans
            k = rate_hz * pulse_rad[i]
            out.append(b * k)
            sig.append(sd * math.sqrt(12.0 / m) / span * k)
        return tuple(out), tuple(sig)


if __name__ == "__main__":
    main()
