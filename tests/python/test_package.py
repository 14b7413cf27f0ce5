"""The `ecmxf` Python package (clients/python) against the real daemon, as a
user runs it: installed with `pip install ./clients/python` (.ci/run does,
into target/py-venv), `ecmxfd --sim` started with $ECMXF_SOCKET pointing
at a private socket, then the README's five-line script and the typed API:
slaves, SDO reads and writes with their errors (the abort code), states,
the layout, inputs as dicts and numpy arrays, a lease writing by entry name
(seen again through the IO slave's loopback), events.

Run by tests/tests/python.rs; by hand:
    ECMXFD=target/debug/ecmxfd target/py-venv/bin/python tests/python/test_package.py
"""

import os
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import ecmxf

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
IO = 2  # the demo network's IO slave: output 0x7000:01 loops back to input 0x6000:01
OUT, IN = "2.0x7000:01", "2.0x6000:01"


class Package(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(prefix="ecmxf-pkg-")
        cls.socket = os.path.join(cls.tmp.name, "ecmxfd.sock")
        os.environ["ECMXF_SOCKET"] = cls.socket
        binary = os.environ.get("ECMXFD", os.path.join(REPO, "target", "debug", "ecmxfd"))
        cls.log = open(os.path.join(cls.tmp.name, "ecmxfd.log"), "w")
        cls.daemon = subprocess.Popen([binary, "--sim", "--status-every", "0"], stdout=cls.log, stderr=cls.log)
        deadline = time.monotonic() + 30
        while True:
            try:
                with ecmxf.connect(wait=1) as c:
                    if c.status().phase == ecmxf.v1.master_pb2.ENGINE_PHASE_RUNNING:
                        break
            except ecmxf.Unreachable:
                pass
            if cls.daemon.poll() is not None or time.monotonic() > deadline:
                cls.tearDownClass()
                raise RuntimeError("ecmxfd --sim did not come up:\n" + open(cls.log.name).read())
            time.sleep(0.1)
        cls.c = ecmxf.connect()

    @classmethod
    def tearDownClass(cls):
        if getattr(cls, "c", None):
            cls.c.close()
        cls.daemon.terminate()
        cls.daemon.wait(10)
        cls.log.close()
        cls.tmp.cleanup()

    def test_1_the_readme_script(self):
        out = subprocess.run(
            [sys.executable, os.path.join(REPO, "clients", "python", "examples", "first_contact.py")],
            capture_output=True,
            text=True,
            timeout=60,
        )
        self.assertEqual(out.returncode, 0, out.stderr)
        lines = out.stdout.splitlines()
        self.assertIn("'TI CiA402 3-axis', 'OP'", lines[0])
        self.assertEqual(lines[1], "vendor id 0x59d")
        samples = int(lines[2].split()[0])
        # `ecmxfd --sim` runs thousands of cycles a second; a loaded host
        # may lose some samples to the stream's age bound, never most.
        self.assertGreater(samples, 500, out.stdout)
        print("five-line script:", " | ".join(lines))

    def test_2_sdo_values_and_errors(self):
        c = self.c
        self.assertEqual(c.sdo_read(1, 0x1018, 1), 0x59D)
        self.assertIsInstance(c.sdo_read(1, 0x1008), str)
        self.assertEqual(c.sdo_write(1, 0x605A, 0, 6), 2)
        self.assertEqual(c.sdo_read(1, 0x605A), 6)
        self.assertEqual(c.sdo_write(1, 0x605A, 0, -1), 2)
        self.assertEqual(c.sdo_read(1, 0x605A), -1)
        self.assertEqual(c.sdo_read(1, 0x1018, 1, type="u32"), 0x59D)
        with self.assertRaises(ecmxf.SdoAbort) as e:
            c.sdo_read(1, 0x2FFF)
        self.assertEqual(e.exception.abort_code, 0x06020000)
        self.assertIn("does not exist", e.exception.meaning)
        self.assertEqual((e.exception.slave, e.exception.object), (1, "0x2fff:00"))
        with self.assertRaises(ecmxf.InvalidArgument) as e:
            c.sdo_read(99, 0x1018, 1)
        self.assertEqual(e.exception.field, "slave")
        self.assertIn("slave 99", str(e.exception))
        with self.assertRaises(ecmxf.InvalidArgument):
            c.sdo_write(1, 0x605A, 0, 1 << 20)  # not an INTEGER16
        with self.assertRaises(ValueError):
            c.sdo_read(1, 0x1018, 1, type="u33")

    def test_3_states_and_layout(self):
        c = self.c
        self.assertEqual(c.state(), "OP")
        self.assertEqual(set(c.states().values()), {"OP"})
        names = [s.name for s in c.slaves()]
        self.assertIn("8io", names)
        layout = c.layout()
        self.assertIn(IN, [e.name for e in layout.inputs()])
        self.assertIn(OUT, [e.name for e in layout.outputs()])
        with self.assertRaises(ValueError):
            c.set_state("operational-ish")

    def test_4_inputs_lease_and_loopback(self):
        c = self.c
        with c.lease([IO], ttl=0.5) as lease:
            for value in (0x5A, 0xA5):
                self.assertEqual(lease.write({OUT: value}), 1)
                seen = None
                for s in c.stream_inputs([IN], duration=2.0):
                    seen = s[IN]
                    if seen == value:
                        break
                self.assertEqual(seen, value, "the IO slave loops its output back")
            time.sleep(1.0)  # two TTLs: kept alive by the lease's thread
            self.assertEqual(lease.write({OUT: 1}), 1)
        with self.assertRaises(ecmxf.FailedPrecondition):
            lease.write({OUT: 2})

        every = list(c.stream_inputs([IN, "1.statusword"], every=10, count=5))
        self.assertEqual(len(every), 5)
        self.assertTrue(all(set(s) == {IN, "1.statusword"} for s in every))
        steps = {b.seq - a.seq for a, b in zip(every, every[1:])}
        self.assertTrue(all(d % 10 == 0 for d in steps), steps)
        try:
            import numpy  # noqa: F401
        except ImportError:
            print("numpy not installed: inputs_array not tried")
            return
        a = c.inputs_array([IN, "1.position_actual"], count=20)
        self.assertEqual(a.shape, (20,))
        self.assertEqual(a.dtype["1.position_actual"].str, "<i4")
        self.assertTrue((a["seq"][1:] > a["seq"][:-1]).all())

    def test_5_events(self):
        c = self.c
        got = []

        def follow():
            for e in c.events():
                got.append(e)
                if e.kind == "STATE_CHANGE" and e.message.to_state == ecmxf.v1.common_pb2.ECAT_STATE_OP:
                    return

        t = threading.Thread(target=follow, daemon=True)
        t.start()
        time.sleep(0.5)
        self.assertEqual(c.set_state("safe_op", slave=IO), "SAFE_OP")
        self.assertEqual(c.set_state("op", slave=IO), "OP")
        t.join(15)
        kinds = [e.kind for e in got]
        self.assertIn("STATE_CHANGE", kinds, kinds)


class EniVariables(unittest.TestCase):
    """config/ecmxfd-eni.toml: the demo network described by an ENI whose
    ProcessImage names the IO slave's data; values by those names."""

    def test_6_values_by_the_eni_variable_names(self):
        with tempfile.TemporaryDirectory(prefix="ecmxf-eni-") as tmp:
            socket = os.path.join(tmp, "ecmxfd.sock")
            binary = os.environ.get("ECMXFD", os.path.join(REPO, "target", "debug", "ecmxfd"))
            config = os.path.join(REPO, "config", "ecmxfd-eni.toml")
            with open(os.path.join(tmp, "log"), "w") as log:
                daemon = subprocess.Popen(
                    [binary, "--config", config, "--socket", socket, "--status-every", "0"], stdout=log, stderr=log
                )
            try:
                deadline = time.monotonic() + 30
                while True:
                    try:
                        c = ecmxf.connect(socket, wait=1)
                        if c.status().phase == ecmxf.v1.master_pb2.ENGINE_PHASE_RUNNING:
                            break
                        c.close()
                    except ecmxf.Unreachable:
                        pass
                    if daemon.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError("ecmxfd did not come up:\n" + open(os.path.join(tmp, "log")).read())
                    time.sleep(0.1)
                with c:
                    out, inp = "IO.Outputs.Outputs 1-8", "IO.Inputs.Inputs 1-8"
                    try:
                        layout = c.layout()
                    except ecmxf.Error as e:
                        # What the daemon did meanwhile says why.
                        raise AssertionError("%s; the daemon's log:\n%s" % (e, open(os.path.join(tmp, "log")).read()))
                    self.assertEqual(layout.entry(inp).name, IN)
                    self.assertEqual(layout.entry(out).variable, out)
                    with c.lease([IO]) as lease:
                        self.assertEqual(lease.write({out: 0x3C}), 1)
                        seen = None
                        for s in c.stream_inputs([inp], duration=2.0):
                            seen = s[inp]
                            if seen == 0x3C:
                                break
                        self.assertEqual(seen, 0x3C, "written and read by the ENI's names")
            finally:
                daemon.terminate()
                daemon.wait(10)


class Unreachable(unittest.TestCase):
    """Nothing listens: the error at once, in ecmxfctl's words."""

    def test_7_a_missing_socket_fails_at_once(self):
        with tempfile.TemporaryDirectory(prefix="ecmxf-none-") as tmp:
            missing = os.path.join(tmp, "ecmxfd.sock")
            start = time.monotonic()
            with self.assertRaises(ecmxf.Unreachable) as caught:
                ecmxf.connect(missing)
            took = time.monotonic() - start
            self.assertLess(took, 0.2, "failed after %.3f s" % took)
            self.assertIn("cannot reach ecmxfd at %s: no socket there" % missing, str(caught.exception))
            # A file nobody listens on: a stale socket.
            import socket as sk

            stale = sk.socket(sk.AF_UNIX, sk.SOCK_STREAM)
            stale.bind(missing)
            stale.close()
            with self.assertRaises(ecmxf.Unreachable) as caught:
                ecmxf.connect(missing)
            self.assertIn("nothing listens on the socket (stale file)", str(caught.exception))


if __name__ == "__main__":
    unittest.main(verbosity=2)
