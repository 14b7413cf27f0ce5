"""ecmxfd as a Sparkplug B edge node, checked by an independent Sparkplug
host: paho-mqtt (PyPI) on a real mosquitto broker (Debian), payloads
decoded with the Eclipse Tahu schema as pysparkplug (PyPI) ships it, not
with ecmxfd's own copy of the .proto.

One scenario, in order (each step builds on the last):
  births in order with unique aliases and seq without gaps; DDATA values
  equal to `ecmxfctl data`; a DCMD output write seen through the IO
  slave's loopback; rebirth on NCMD; DDEATH within 1 s of unplugging the IO
  slave and DBIRTH after replug; the broker restarted while the network
  runs (the node reconnects with the next bdSeq and rebirths, the engine
  has no FIFO alarm); NDEATH with the right bdSeq when the daemon is
  killed with SIGKILL (the broker sends the will); and a daemon with
  `commands = "none"` refusing NCMD and DCMD.

Run by tests/tests/sparkplug.rs; by hand (after `cargo build`):
    ECMXFD=target/debug/ecmxfd ECMXFCTL=target/debug/ecmxfctl \
    ECMXF_SIM=target/debug/ecmxf-sim MOSQUITTO=/usr/sbin/mosquitto \
    target/py-venv/bin/python tests/python/test_sparkplug.py
"""

import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
import unittest

import paho.mqtt.client as mqtt
from pysparkplug._protobuf import sparkplug_b_pb2 as spb  # the Eclipse Tahu schema

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
TARGET = os.path.join(REPO, "target", "debug")
GROUP = "ecmxf-test"
NODE = "gw-%d" % os.getpid()
IO = "slave-2"  # the demo network's IO slave: output 0x7000:01 loops back to input 0x6000:01

# Sparkplug datatypes (spec 6.4.16) and where their values are.
INT_TYPES = {1: 8, 2: 16, 3: 32}  # Int8..Int32: int_value, two's complement of their width
UINT_INT = {5, 6, 7}  # UInt8..UInt32: int_value
LONG = {4, 8}  # Int64, UInt64: long_value


def metric_value(m):
    """A metric's value as Python sees it (pysparkplug's reading)."""
    t = m.datatype
    if t in INT_TYPES:
        bits = INT_TYPES[t]
        v = m.int_value & ((1 << bits) - 1)
        return v - (1 << bits) if v >= 1 << (bits - 1) else v
    if t in UINT_INT:
        return m.int_value
    if t == 4:
        v = m.long_value
        return v - (1 << 64) if v >= 1 << 63 else v
    if t == 8:
        return m.long_value
    if t == 9:
        return m.float_value
    if t == 10:
        return m.double_value
    if t == 11:
        return m.boolean_value
    if t == 12:
        return m.string_value
    if t == 17:
        return bytes(m.bytes_value)
    raise AssertionError("unexpected datatype %d" % t)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Host:
    """A Sparkplug host application: subscribes to the group, keeps every
    message in arrival order, and the node's metrics by alias as births
    define them and data updates them."""

    def __init__(self, port):
        self.lock = threading.Condition()
        self.messages = []  # (time, kind, device, payload)
        self.client = mqtt.Client(client_id="ecmxf-test-host-%d" % os.getpid(), clean_session=True)
        self.client.on_message = self._on_message
        self.client.on_connect = lambda c, u, f, rc: c.subscribe("spBv1.0/%s/#" % GROUP, qos=1)
        self.port = port
        self.client.reconnect_delay_set(0.2, 1)
        self.client.connect("127.0.0.1", port, keepalive=10)
        self.client.loop_start()

    def _on_message(self, client, userdata, msg):
        levels = msg.topic.split("/")
        if len(levels) < 4 or levels[3] != NODE:
            return
        p = spb.Payload()
        p.ParseFromString(msg.payload)
        with self.lock:
            self.messages.append((time.monotonic(), levels[2], levels[4] if len(levels) > 4 else None, p))
            self.lock.notify_all()

    def wait_for(self, what, timeout, since=0):
        """The first message from index `since` on for which what(kind,
        device, payload) holds, and its index."""
        deadline = time.monotonic() + timeout
        with self.lock:
            while True:
                for i in range(since, len(self.messages)):
                    _, kind, device, p = self.messages[i]
                    if what(kind, device, p):
                        return i, self.messages[i]
                left = deadline - time.monotonic()
                if left <= 0:
                    kinds = [(m[1], m[2]) for m in self.messages[since:]][-20:]
                    raise AssertionError("no such message within %.1f s; last seen: %s" % (timeout, kinds))
                self.lock.wait(left)

    def count(self):
        with self.lock:
            return len(self.messages)

    def state(self, since):
        """Every device's metrics by name from the last births from index
        `since` on, updated by the data after them: {device: {name: value}}."""
        with self.lock:
            msgs = list(self.messages[since:])
        names, values = {}, {}
        for _, kind, device, p in msgs:
            if kind in ("NBIRTH", "DBIRTH"):
                for m in p.metrics:
                    names[(device, m.alias)] = m.name
                    values.setdefault(device, {})[m.name] = metric_value(m)
            elif kind in ("NDATA", "DDATA"):
                if device not in values:
                    continue  # born before `since`
                for m in p.metrics:
                    name = names.get((device, m.alias))
                    assert name is not None, "%s %s: alias %d never born" % (kind, device, m.alias)
                    values[device][name] = metric_value(m)
            elif kind == "DDEATH":
                values.pop(device, None)
        return values

    def command(self, device, name, datatype, **value):
        p = spb.Payload()
        p.timestamp = int(time.time() * 1000)
        m = p.metrics.add()
        m.name = name
        m.datatype = datatype
        for k, v in value.items():
            setattr(m, k, v)
        if device is None:
            topic = "spBv1.0/%s/NCMD/%s" % (GROUP, NODE)
        else:
            topic = "spBv1.0/%s/DCMD/%s/%s" % (GROUP, NODE, device)
        self.client.publish(topic, p.SerializeToString(), qos=1).wait_for_publish(5)

    def close(self):
        self.client.loop_stop()
        self.client.disconnect()


def metric(p, name):
    for m in p.metrics:
        if m.name == name:
            return m
    raise AssertionError("no metric %r in %s" % (name, [m.name for m in p.metrics]))


class Sparkplug(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="ecmxf-spb-")
        cls.port = free_port()
        cls.procs = {}
        cls.start_broker()
        cls.sim_socket = os.path.join(cls.tmp, "sim.sock")
        sim = os.environ.get("ECMXF_SIM", os.path.join(TARGET, "ecmxf-sim"))
        cls.sim_bin = sim
        cls.procs["sim"] = subprocess.Popen(
            [sim, "serve", "--socket", cls.sim_socket], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        wait_until(lambda: os.path.exists(cls.sim_socket), 10, "ecmxf-sim's socket")
        cls.host = Host(cls.port)
        cls.start_daemon("operator")

    @classmethod
    def start_broker(cls):
        conf = os.path.join(cls.tmp, "mosquitto.conf")
        with open(conf, "w") as f:
            f.write("listener %d 127.0.0.1\nallow_anonymous true\npersistence false\n" % cls.port)
        binary = os.environ.get("MOSQUITTO") or shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        with open(os.path.join(cls.tmp, "mosquitto.log"), "a") as log:
            cls.procs["broker"] = subprocess.Popen([binary, "-c", conf, "-v"], stdout=log, stderr=log)

        def listening():
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", cls.port)) == 0

        wait_until(listening, 10, "mosquitto listening on %d" % cls.port)

    @classmethod
    def start_daemon(cls, commands, extra=""):
        config = cls.write_config(commands, extra)
        binary = os.environ.get("ECMXFD", os.path.join(TARGET, "ecmxfd"))
        cls.daemon_log = os.path.join(cls.tmp, "ecmxfd-%s.log" % commands)
        with open(cls.daemon_log, "w") as log:
            cls.procs["daemon"] = subprocess.Popen(
                [binary, "--config", config, "--status-every", "0"], stdout=log, stderr=log
            )

    @classmethod
    def write_config(cls, commands, extra=""):
        cls.socket = os.path.join(cls.tmp, "ecmxfd.sock")
        config = os.path.join(cls.tmp, "ecmxfd.toml")
        with open(config, "w") as f:
            f.write(
                "version = 1\n[link]\nbackend = \"sim-socket\"\nsocket = \"%s\"\n"
                "[chip]\nready_timeout_ms = 1000\n[realtime]\npriority = 0\nlock_memory = false\nspin_us = 0\n"
                "[cycle]\nfifo_rx_depth = 255\nfifo_tx_depth = 40\nfifo_low = 128\nfifo_high = 240\n"
                "[api]\nsocket = \"%s\"\n"
                "[sparkplug]\nbroker = \"mqtt://127.0.0.1:%d\"\ngroup_id = \"%s\"\nnode_id = \"%s\"\n"
                "data_period_ms = 100\ndiagnostics_period_ms = 500\ncommands = \"%s\"\n%s"
                % (cls.sim_socket, cls.socket, cls.port, GROUP, NODE, commands, extra)
            )
        return config

    @classmethod
    def tearDownClass(cls):
        cls.host.close()
        for p in cls.procs.values():
            if p.poll() is None:
                p.kill()
                p.wait(10)
        if os.environ.get("ECMXF_KEEP"):
            print("kept", cls.tmp)
        else:
            shutil.rmtree(cls.tmp, ignore_errors=True)

    def ctl(self, *args):
        binary = os.environ.get("ECMXFCTL", os.path.join(TARGET, "ecmxfctl"))
        out = subprocess.run(
            [binary, "--socket", self.socket, "--json"] + list(args), capture_output=True, text=True, timeout=30
        )
        self.assertEqual(out.returncode, 0, out.stderr)
        return json.loads(out.stdout)

    def sim(self, *words):
        subprocess.run([self.sim_bin, "ctl", "--socket", self.sim_socket] + list(words), check=True, timeout=10)

    def log(self):
        with open(self.daemon_log) as f:
            return f.read()

    # The steps, in order.

    def test_01_births_in_order_aliases_unique_and_seq_without_gaps(self):
        h = self.host
        i, (_, _, _, nbirth) = h.wait_for(lambda k, d, p: k == "NBIRTH", 30)
        self.__class__.first_birth = i
        self.assertEqual(nbirth.seq, 0)
        self.assertEqual(metric(nbirth, "bdSeq").datatype, 8)  # UInt64
        self.assertEqual(metric(nbirth, "bdSeq").long_value, 0)
        self.assertIs(metric(nbirth, "Node Control/Rebirth").boolean_value, False)
        self.assertTrue(metric(nbirth, "Engine/Phase").string_value)
        # Then the devices: every slave of the demo network, each born once.
        for n in range(3):
            h.wait_for(lambda k, d, p, n=n: k == "DBIRTH" and d == "slave-%d" % n, 30, i)
        time.sleep(1.0)
        with h.lock:
            msgs = list(h.messages[i:])
        kinds = [m[1] for m in msgs]
        self.assertNotIn("NBIRTH", kinds[1:], "one NBIRTH per connection")
        # Every device is born before its data, and born once.
        births = [(j, m[2]) for j, m in enumerate(msgs) if m[1] == "DBIRTH"]
        self.assertEqual(sorted(d for _, d in births), ["slave-0", "slave-1", "slave-2"])
        for j, (_, kind, device, _) in enumerate(msgs):
            if kind == "DDATA":
                self.assertLess(dict((d, b) for b, d in births)[device], j, "DDATA of %s before its DBIRTH" % device)
        # Aliases: unique across the node and its devices, and every one with a name.
        aliases = {}
        for _, kind, device, p in msgs:
            if kind in ("NBIRTH", "DBIRTH"):
                for m in p.metrics:
                    self.assertTrue(m.name and m.HasField("alias"), m)
                    self.assertNotIn(m.alias, aliases, "alias %d of %s/%s reused" % (m.alias, device, m.name))
                    aliases[m.alias] = (device, m.name)
        for _, kind, device, p in msgs:
            if kind in ("NDATA", "DDATA"):
                for m in p.metrics:
                    self.assertFalse(m.name, "data by alias only")
                    self.assertEqual(aliases[m.alias][0], device)
        # seq: 0, 1, 2... modulo 256, without a gap.
        seqs = [p.seq for (_, k, _, p) in msgs]
        for a, b in zip(seqs, seqs[1:]):
            self.assertEqual(b, (a + 1) % 256, seqs)
        print("births: NBIRTH + %d DBIRTH, %d aliases, %d messages in order" % (len(births), len(aliases), len(msgs)))

    def test_02_ddata_values_equal_ecmxfctl_data(self):
        # Values that hold still across two reads of `ecmxfctl data` must be
        # what the host has after the data in between.
        before = {e["name"]: e for e in self.ctl("data")["entries"]}
        time.sleep(0.6)
        state = self.host.state(self.first_birth)
        after = {e["name"]: e for e in self.ctl("data")["entries"]}
        compared = 0
        for name, e in after.items():
            if before.get(name, {}).get("value") != e["value"]:
                continue
            slave, rest = name.split(".", 1)
            folder = "Outputs/" if e["direction"] == "output" else "Inputs/"
            have = state["slave-" + slave].get(folder + rest)
            self.assertIsNotNone(have, "%s: no metric %s%s in %s" % (name, folder, rest, sorted(state["slave-" + slave])))
            want = e["value"]
            if isinstance(have, bool):
                want = bool(want)
            self.assertEqual(have, want, name)
            compared += 1
        self.assertGreater(compared, 20, "too few steady values to compare")
        print("ddata: %d values equal to ecmxfctl data" % compared)

    def test_03_dcmd_output_write_loops_back(self):
        h = self.host
        since = h.count()
        h.command(IO, "Outputs/0x7000:01", 5, int_value=1)  # UInt8
        i, (_, _, _, p) = h.wait_for(
            lambda k, d, p: k == "DDATA" and d == IO and any(m.int_value == 1 for m in p.metrics), 10, since
        )
        wait_until(lambda: self.host.state(self.first_birth)[IO].get("Inputs/0x6000:01") == 1, 5, "loopback in DDATA")
        entries = {e["name"]: e["value"] for e in self.ctl("data")["entries"]}
        self.assertEqual(entries["2.0x7000:01"], 1)
        self.assertEqual(entries["2.0x6000:01"], 1)
        h.command(IO, "Outputs/0x7000:01", 5, int_value=0)
        wait_until(lambda: self.host.state(self.first_birth)[IO].get("Inputs/0x6000:01") == 0, 5, "loopback back to 0")
        print("dcmd: Outputs/0x7000:01 = 1 came back as Inputs/0x6000:01 (and ecmxfctl data agrees)")

    def test_04_rebirth_on_ncmd(self):
        h = self.host
        since = h.count()
        h.command(None, "Node Control/Rebirth", 11, boolean_value=True)
        i, (_, _, _, p) = h.wait_for(lambda k, d, p: k == "NBIRTH", 10, since)
        self.assertEqual(p.seq, 0)
        self.assertEqual(metric(p, "bdSeq").long_value, 0, "a rebirth keeps the connection's bdSeq")
        for n in range(3):
            h.wait_for(lambda k, d, p, n=n: k == "DBIRTH" and d == "slave-%d" % n, 10, i)
        # A host repeating Rebirth gets one more set of births a second
        # later, not one per request.
        since = h.count()
        for _ in range(5):
            h.command(None, "Node Control/Rebirth", 11, boolean_value=True)
        j, _ = h.wait_for(lambda k, d, p: k == "NBIRTH", 5, since)
        time.sleep(1.5)
        with h.lock:
            nbirths = [m for m in h.messages[since:] if m[1] == "NBIRTH"]
        # One a second after the last births (two when those were already
        # older than a second on a stalled host), never five.
        self.assertIn(len(nbirths), (1, 2), "5 requests at once: %d sets of births" % len(nbirths))
        self.__class__.first_birth = j
        print("rebirth: NBIRTH seq 0 and 3 DBIRTH after NCMD; 5 more requests at once: one more set of births")

    def test_05_ddeath_on_unplug_and_dbirth_on_replug(self):
        h = self.host
        since = h.count()
        t0 = time.monotonic()
        self.sim("unplug", "2")
        i, (t, _, _, _) = h.wait_for(lambda k, d, p: k == "DDEATH" and d == IO, 5, since)
        took = t - t0
        self.assertLess(took, 1.0, "DDEATH %.3f s after the unplug" % took)
        time.sleep(0.5)
        self.sim("replug", "2")
        j, (t2, _, _, _) = h.wait_for(lambda k, d, p: k == "DBIRTH" and d == IO, 30, i)
        print("unplug: DDEATH %s after %.0f ms; replug: DBIRTH after %.1f s" % (IO, took * 1000, t2 - t0 - 0.5))
        # Process data flows again for the device: a write comes back.
        h.command(IO, "Outputs/0x7000:01", 5, int_value=1)
        wait_until(lambda: self.host.state(j)[IO].get("Inputs/0x6000:01") == 1, 10, "loopback after replug")
        h.command(IO, "Outputs/0x7000:01", 5, int_value=0)
        wait_until(lambda: self.host.state(j)[IO].get("Inputs/0x6000:01") == 0, 10, "loopback back to 0")

    def test_06_broker_restart_reconnects_rebirths_and_the_engine_runs_on(self):
        h = self.host
        before = self.ctl("master")["counters"]
        since = h.count()
        self.procs["broker"].kill()
        self.procs["broker"].wait(10)
        time.sleep(1.5)
        self.start_broker()
        i, (_, _, _, p) = h.wait_for(lambda k, d, p: k == "NBIRTH", 40, since)
        bd_seq = metric(p, "bdSeq").long_value
        # Each CONNECT's will has the next bdSeq (attempts while the broker
        # was down may count too): a host tells this session from the last.
        self.assertTrue(0 < bd_seq < 10, bd_seq)
        self.__class__.bd_seq = bd_seq
        self.assertEqual(p.seq, 0)
        for n in range(3):
            h.wait_for(lambda k, d, p, n=n: k == "DBIRTH" and d == "slave-%d" % n, 10, i)
        self.__class__.first_birth = i
        # The births hold: no device dies and is born again once the node
        # is back (a host would see every device flap).
        time.sleep(4)
        with h.lock:
            flaps = [(m[1], m[2]) for m in h.messages[i + 1:] if m[1] in ("DDEATH", "NBIRTH", "NDEATH")]
            rebirths = [m[2] for m in h.messages[i + 1:] if m[1] == "DBIRTH"]
        self.assertEqual(flaps, [], "after the reconnect's births")
        self.assertEqual(sorted(rebirths), ["slave-%d" % n for n in range(3)], "one DBIRTH per device")
        after = self.ctl("master")["counters"]
        for key in ("fifo_alarms", "recoveries"):
            self.assertEqual(after.get(key, 0), before.get(key, 0), "%s: %s -> %s" % (key, before, after))
        print("broker restart: NBIRTH bdSeq %d and births again; fifo_alarms and recoveries unchanged" % bd_seq)

    def test_07_ndeath_with_the_births_bdseq_when_killed(self):
        h = self.host
        since = h.count()
        self.procs["daemon"].send_signal(signal.SIGKILL)
        self.procs["daemon"].wait(10)
        i, (_, _, _, p) = h.wait_for(lambda k, d, p: k == "NDEATH", 10, since)
        self.assertEqual(metric(p, "bdSeq").long_value, self.bd_seq, "NDEATH matches the session's NBIRTH")
        self.assertFalse(p.HasField("seq"), "NDEATH carries no seq")
        print("kill -9: the broker sent NDEATH bdSeq %d" % self.bd_seq)

    def test_08_commands_refused_when_disabled(self):
        h = self.host
        since = h.count()
        self.start_daemon("none")
        i, _ = h.wait_for(lambda k, d, p: k == "NBIRTH", 40, since)
        h.wait_for(lambda k, d, p: k == "DBIRTH" and d == IO, 30, i)
        after_births = h.count()
        h.command(None, "Node Control/Rebirth", 11, boolean_value=True)
        h.command(IO, "Outputs/0x7000:01", 5, int_value=1)
        wait_until(lambda: "DCMD to slave-2 refused" in self.log(), 5, "the DCMD refusal in the log")
        self.assertIn("Rebirth refused", self.log())
        time.sleep(0.5)
        with h.lock:
            later = [m[1] for m in h.messages[after_births:]]
        self.assertNotIn("NBIRTH", later)
        entries = {e["name"]: e["value"] for e in self.ctl("data")["entries"]}
        self.assertEqual(entries["2.0x7000:01"], 0, "the refused DCMD wrote nothing")
        # The refusals are counted in the node's diagnostics.
        h.wait_for(
            lambda k, d, p: k == "NDATA" and any(m.long_value >= 2 for m in p.metrics if m.alias == self.refused_alias(i)),
            5,
            after_births,
        )
        print("commands = none: NCMD Rebirth and DCMD refused, logged and counted")

    def test_09_births_wait_for_the_primary_host(self):
        h = self.host
        self.procs["daemon"].terminate()
        self.procs["daemon"].wait(10)
        state = "spBv1.0/STATE/scada-%d" % os.getpid()
        online = lambda up: json.dumps({"online": up, "timestamp": int(time.time() * 1000)})
        h.client.publish(state, online(False), qos=1, retain=True).wait_for_publish(5)
        since = h.count()
        self.start_daemon("observer", 'primary_host_id = "scada-%d"\n' % os.getpid())
        wait_until(lambda: "waiting for the primary host" in self.log(), 30, "the node waiting for the host")
        time.sleep(1.0)
        self.assertEqual(h.count(), since, "no birth while the primary host is offline")
        h.client.publish(state, online(True), qos=1, retain=True).wait_for_publish(5)
        i, _ = h.wait_for(lambda k, d, p: k == "NBIRTH", 10, since)
        h.wait_for(lambda k, d, p: k == "DBIRTH" and d == IO, 30, i)
        # The host goes offline: the node says NDEATH and waits again.
        since = h.count()
        h.client.publish(state, online(False), qos=1, retain=True).wait_for_publish(5)
        h.wait_for(lambda k, d, p: k == "NDEATH", 10, since)
        time.sleep(2.5)
        with h.lock:
            self.assertNotIn("NBIRTH", [m[1] for m in h.messages[since:]], "births while the host is offline")
        h.client.publish(state, online(True), qos=1, retain=True).wait_for_publish(5)
        h.wait_for(lambda k, d, p: k == "NBIRTH", 10, since)
        h.client.publish(state, b"", qos=1, retain=True).wait_for_publish(5)  # clear the retained STATE
        print("primary host: births only while its STATE is online; NDEATH when it goes offline, births when back")

    def test_10_sighup_restarts_the_node_not_the_bus(self):
        h = self.host
        with h.lock:
            births = [m for m in h.messages if m[1] == "NBIRTH"]
        bd_seq = metric(births[-1][3], "bdSeq").long_value
        before = self.ctl("master")
        since = h.count()
        # The same daemon, its [sparkplug] changed (no primary host, commands
        # observer): SIGHUP.
        self.write_config("observer")
        self.procs["daemon"].send_signal(signal.SIGHUP)
        i, (_, _, _, death) = h.wait_for(lambda k, d, p: k == "NDEATH", 10, since)
        self.assertEqual(metric(death, "bdSeq").long_value, bd_seq, "the old session's death")
        j, (_, _, _, birth) = h.wait_for(lambda k, d, p: k == "NBIRTH", 10, i)
        self.assertEqual(metric(birth, "bdSeq").long_value, (bd_seq + 1) % 256, "bdSeq goes on")
        h.wait_for(lambda k, d, p: k == "DBIRTH" and d == IO, 10, j)
        wait_until(lambda: "[sparkplug] applied" in self.log(), 5, "the reload in the log")
        after = self.ctl("master")
        self.assertEqual(after["phase"], "RUNNING")
        self.assertEqual(after["counters"]["recoveries"], before["counters"]["recoveries"], "the bus ran on")
        self.assertGreater(after["counters"]["input_frames"], before["counters"]["input_frames"])
        # ecmxfctl master shows the node (GetStatus.sparkplug).
        wait_until(lambda: self.ctl("master").get("sparkplug", {}).get("connected"), 5, "ecmxfctl master: connected")
        sp = self.ctl("master")["sparkplug"]
        self.assertEqual(sp["bd_seq"], (bd_seq + 1) % 256)
        self.assertEqual(sp["broker"], "mqtt://127.0.0.1:%d" % self.port)
        self.assertGreater(sp["published"], 0)
        print("SIGHUP: NDEATH bdSeq %d, NBIRTH bdSeq %d, the bus ran on" % (bd_seq, (bd_seq + 1) % 256))

    def refused_alias(self, birth):
        with self.host.lock:
            p = self.host.messages[birth][3]
        return metric(p, "Sparkplug/Commands Refused").alias


def wait_until(cond, timeout, what):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("timed out waiting for " + what)
        time.sleep(0.05)


if __name__ == "__main__":
    unittest.main(verbosity=2)
