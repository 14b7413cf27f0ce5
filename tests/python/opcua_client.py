"""An independent OPC UA client (asyncua, from PyPI) for tests/tests/opcua.rs.

    opcua_client.py URL browse
        The daemon's address space as JSON: the master's variables, and per
        slave its properties and variables and its Inputs/Outputs entries
        (browse name, display name, data type, value, status, source time).
    opcua_client.py URL subscribe SECONDS SAMPLING_MS NODE_ID...
        One subscription with a monitored item per node (string node ids of
        the daemon's namespace) at the sampling interval, for SECONDS: each
        data change as JSON with the local time it arrived.
    opcua_client.py URL events SECONDS PUBLISHING_MS
        One event subscription on the Server object (BaseEventType: Message,
        Severity, SourceNode, SourceName, Time) for SECONDS, "subscribed"
        once it is set up: each event as JSON with the local time it arrived.
    opcua_client.py URL load SESSIONS ITEMS SAMPLING_MS SECONDS
        For ecmxfd-opcua-bench: SESSIONS sessions with one subscription
        each, ITEMS monitored items in all over every variable of the
        EtherCAT object and its slaves (each session a window of them),
        "subscribed" once all are set up, then SECONDS of data changes
        counted: {"changes": N, "per_second": R}.

    opcua_client.py URL makecert DIR NAME
        A client application certificate (DIR/NAME.der, key DIR/NAME.pem,
        application URI urn:ecmxf:test:NAME) as OPC UA clients make their
        own; prints {"thumbprint": SHA-1 hex}.
    opcua_client.py URL connect DIR NAME POLICY [USER PASSWORD]
        One signed and encrypted session (POLICY: Basic256Sha256 or
        Aes128Sha256RsaOaep) with certificate NAME, as USER if given
        ("cert:NAME2": the X.509 user identity of certificate NAME2), else
        anonymous; prints {"ok": bool,
        "error": text, "role_write": UserAccessLevel has CurrentWrite for
        the first output variable}.
    opcua_client.py URL writes DIR OUT_ID IN_ID
        Output writes and their leases: an anonymous session, then
        operators op1 and op2 (passwords op1-secret, op2-secret, with
        certificates DIR/op1 and DIR/op2) write OUT_ID and read IN_ID back;
        each step's status codes and diagnostics as JSON.
    opcua_client.py URL axis DIR N
        Axis N's methods: Enable anonymously (refused), then as op1
        Disable, Enable and SetMode 9 (CSV), with the State variable read
        after each; as JSON.
    opcua_client.py URL dictionary DIR SLAVE ENTRY
        Dictionary entry ENTRY ("0x6083:00") of slave SLAVE, once it is
        there: read (MaxAge 0), written anonymously (refused) and by op1,
        then read with MaxAge 60 s (the value uploaded last) and 0 (the
        device's now); as JSON.
    opcua_client.py URL methods DIR SLAVE
        The methods of slave SLAVE: SdoUpload anonymously, SdoDownload
        anonymously and as op1 (a good value, a mistyped one), RequestState
        PREOP then OP as op1; each result as JSON.

Everything is asked as a generic client asks (Browse, Read, CreateSubscription,
CreateMonitoredItems); nothing here knows how ecmxfd builds its nodes beyond
the namespace URI and the EtherCAT object's node id.
"""

import asyncio
import json
import sys
import time

from asyncua import Client, ua

NAMESPACE = "urn:ecmxf:ecmxfd"


def millis(t):
    return None if t is None else t.timestamp() * 1000.0


async def variable(node):
    dv = await node.read_data_value(raise_on_bad_status=False)
    value = dv.Value.Value if dv.Value is not None else None
    if isinstance(value, (bytes, bytearray)):
        value = value.hex()
    data_type = await node.read_data_type()
    return {
        "display": (await node.read_display_name()).Text,
        "data_type": data_type.Identifier if data_type.NamespaceIndex == 0 else str(data_type),
        "value": value,
        "status": dv.StatusCode.name,
        "source_ms": millis(dv.SourceTimestamp),
        "description": (await node.read_description()).Text,
    }


async def browse(client, ns):
    root = client.get_node(ua.NodeId("EtherCAT", ns))
    out = {"master": {}, "slaves": []}
    slaves_folder = None
    for child in await root.get_children():
        name = (await child.read_browse_name()).Name
        if await child.read_node_class() == ua.NodeClass.Variable:
            out["master"][name] = (await variable(child))["value"]
        elif name == "Slaves":
            slaves_folder = child
    for slave in await slaves_folder.get_children():
        entry = {"display": (await slave.read_display_name()).Text, "entries": []}
        for child in await slave.get_children():
            name = (await child.read_browse_name()).Name
            cls = await child.read_node_class()
            if cls == ua.NodeClass.Variable:
                entry[name] = (await variable(child))["value"]
                continue
            if cls == ua.NodeClass.Method:
                entry.setdefault("methods", []).append(name)
                continue
            if name not in ("Inputs", "Outputs"):
                entry.setdefault("folders", []).append(name)
                continue
            for v in await child.get_children():
                described = await variable(v)
                described["folder"] = name
                described["browse_name"] = (await v.read_browse_name()).Name
                described["node_id"] = v.nodeid.Identifier
                entry["entries"].append(described)
        out["slaves"].append(entry)
    return out


class Changes:
    def __init__(self):
        self.seen = []

    def datachange_notification(self, node, val, data):
        dv = data.monitored_item.Value
        if isinstance(val, (bytes, bytearray)):
            val = val.hex()
        self.seen.append(
            {
                "node_id": node.nodeid.Identifier,
                "value": val,
                "status": dv.StatusCode.name,
                "source_ms": millis(dv.SourceTimestamp),
                "arrived_ms": time.time() * 1000.0,
            }
        )


async def subscribe(client, ns, seconds, sampling_ms, ids):
    handler = Changes()
    sub = await client.create_subscription(sampling_ms, handler)
    nodes = [client.get_node(ua.NodeId(i, ns)) for i in ids]
    await sub.subscribe_data_change(nodes, sampling_interval=sampling_ms)
    # Ready: the caller starts changing things now.
    print("subscribed", flush=True)
    await asyncio.sleep(seconds)
    await sub.delete()
    return handler.seen


async def variables_under(node, out):
    for child in await node.get_children():
        cls = await child.read_node_class()
        if cls == ua.NodeClass.Variable:
            # Properties (identity) are static; the rest change.
            if (await child.read_type_definition()) != ua.NodeId(ua.ObjectIds.PropertyType):
                out.append(child.nodeid)
        elif cls == ua.NodeClass.Object:
            await variables_under(child, out)


class Events:
    def __init__(self):
        self.seen = []

    def event_notification(self, event):
        self.seen.append(
            {
                "message": event.Message.Text,
                "severity": event.Severity,
                "source_node": str(event.SourceNode.Identifier),
                "source_name": event.SourceName,
                "time_ms": millis(event.Time),
                "arrived_ms": time.time() * 1000.0,
            }
        )


async def events(client, seconds, publishing_ms):
    handler = Events()
    sub = await client.create_subscription(publishing_ms, handler)
    await sub.subscribe_events(client.nodes.server, ua.ObjectIds.BaseEventType)
    print("subscribed", flush=True)
    await asyncio.sleep(seconds)
    await sub.delete()
    return handler.seen


class Counter:
    def __init__(self):
        self.changes = 0

    def datachange_notification(self, node, val, data):
        self.changes += 1


async def load(url, sessions, items, sampling_ms, seconds):
    clients = [Client(url=url, timeout=30) for _ in range(sessions)]
    for c in clients:
        await c.connect()
    ns = await clients[0].get_namespace_index(NAMESPACE)
    ids = []
    await variables_under(clients[0].get_node(ua.NodeId("EtherCAT", ns)), ids)
    per = items // sessions
    counter = Counter()
    for k, c in enumerate(clients):
        window = [ids[(k * len(ids) // sessions + i) % len(ids)] for i in range(per)]
        sub = await c.create_subscription(sampling_ms, counter)
        await sub.subscribe_data_change([c.get_node(i) for i in window], sampling_interval=sampling_ms)
    print("subscribed", flush=True)
    start_changes, t0 = counter.changes, time.time()
    await asyncio.sleep(seconds)
    n = counter.changes - start_changes
    result = {"changes": n, "per_second": n / (time.time() - t0), "variables": len(ids)}
    for c in clients:
        await c.disconnect()
    return result


def cert_files(folder, name):
    return f"{folder}/{name}.der", f"{folder}/{name}.pem"


async def makecert(folder, name):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID
    from pathlib import Path

    from asyncua.crypto.cert_gen import setup_self_signed_certificate

    cert, key = cert_files(folder, name)
    await setup_self_signed_certificate(
        Path(key),
        Path(cert),
        f"urn:ecmxf:test:{name}",
        "localhost",
        [ExtendedKeyUsageOID.CLIENT_AUTH],
        {"commonName": name},
    )
    with open(cert, "rb") as f:
        der = f.read()
    return {"thumbprint": x509.load_der_x509_certificate(der).fingerprint(hashes.SHA1()).hex()}


async def secure_client(url, folder, name, user=None, password=None, policy="Basic256Sha256"):
    cert, key = cert_files(folder, name)
    client = Client(url=url, timeout=10)
    client.application_uri = f"urn:ecmxf:test:{name}"
    await client.set_security_string(f"{policy},SignAndEncrypt,{cert},{key}")
    if user is not None and user.startswith("cert:"):
        # An X.509 user identity token: certificate and key DIR/NAME.
        from pathlib import Path

        user_cert, user_key = cert_files(folder, user.removeprefix("cert:"))
        await client.load_client_certificate(user_cert)
        await client.load_private_key(Path(user_key))
    elif user is not None:
        client.set_user(user)
        client.set_password(password)
    await client.connect()
    return client


def status_of(e):
    code = getattr(e, "code", None)
    if code is not None:
        return ua.StatusCode(code).name
    return type(e).__name__ + ": " + str(e)


async def write_diagnosed(client, node_id, variant):
    """A Write asking for the operation's additional info (the text a
    refusal gives): (status name, additional info)."""
    from asyncua.ua.ua_binary import struct_from_binary

    params = ua.WriteParameters()
    wv = ua.WriteValue()
    wv.NodeId = node_id
    wv.AttributeId = ua.AttributeIds.Value
    wv.Value = ua.DataValue(variant)
    params.NodesToWrite = [wv]
    request = ua.WriteRequest()
    request.Parameters = params
    # OperationAdditionalInfo (OPC 10000-4 7.32, ReturnDiagnostics).
    request.RequestHeader.ReturnDiagnostics = 0x80
    data = await client.uaclient.protocol.send_request(request)
    response = struct_from_binary(ua.WriteResponse, data)
    infos = response.DiagnosticInfos or []
    info = infos[0].AdditionalInfo if infos else None
    return response.Results[0].name, info


async def output_variant(client, node_id, value):
    node = client.get_node(node_id)
    vtype = await node.read_data_type_as_variant_type()
    return ua.Variant(value, vtype)


async def read_back(client, in_id, want, within_s=2.0):
    end = time.time() + within_s
    while True:
        v = await client.get_node(in_id).read_value()
        if v == want or time.time() > end:
            return v
        await asyncio.sleep(0.02)


async def writes(url, folder, out_name, in_name):
    out = {}
    anon = Client(url=url, timeout=10)
    await anon.connect()
    ns = await anon.get_namespace_index(NAMESPACE)
    out_id, in_id = ua.NodeId(out_name, ns), ua.NodeId(in_name, ns)
    before = await anon.get_node(out_id).read_value()
    out["anonymous"] = await write_diagnosed(anon, out_id, await output_variant(anon, out_id, 0x3C))
    out["anonymous_changed"] = (await anon.get_node(out_id).read_value()) != before
    op1 = await secure_client(url, folder, "op1", "op1", "op1-secret")
    out["op1"] = await write_diagnosed(op1, out_id, await output_variant(op1, out_id, 0x5A))
    out["op1_read_back"] = await read_back(op1, in_id, 0x5A)
    op2 = await secure_client(url, folder, "op2", "op2", "op2-secret")
    out["op2_while_op1"] = await write_diagnosed(op2, out_id, await output_variant(op2, out_id, 0x66))
    out["after_op2"] = await op2.get_node(out_id).read_value()
    await op1.disconnect()
    # The lease goes with the session; the keeper runs 4 times per lease
    # time-to-live.
    end = time.time() + 3.0
    while True:
        status, info = await write_diagnosed(op2, out_id, await output_variant(op2, out_id, 0x66))
        if status == "Good" or time.time() > end:
            break
        await asyncio.sleep(0.1)
    out["op2_after_op1_closed"] = (status, info)
    out["op2_read_back"] = await read_back(op2, in_id, 0x66)
    await op2.disconnect()
    await anon.disconnect()
    return out


async def call(obj, method, *args):
    try:
        outputs = await obj.call_method(method, *args)
        # asyncua gives one output as itself, several as a list.
        if not isinstance(outputs, list):
            outputs = [] if outputs is None else [outputs]
        return {"status": "Good", "outputs": outputs}
    except ua.UaStatusCodeError as e:
        return {"status": status_of(e)}


async def methods(url, folder, slave):
    out = {}
    anon = Client(url=url, timeout=10)
    await anon.connect()
    ns = await anon.get_namespace_index(NAMESPACE)
    obj = anon.get_node(ua.NodeId(f"EtherCAT.Slaves.{slave}", ns))
    m = lambda name: ua.NodeId(f"EtherCAT.Slaves.{slave}.{name}", ns)  # noqa: E731
    u16 = lambda v: ua.Variant(v, ua.VariantType.UInt16)  # noqa: E731
    u8 = lambda v: ua.Variant(v, ua.VariantType.Byte)  # noqa: E731
    r = await call(obj, m("SdoUpload"), u16(0x1018), u8(1))
    out["upload_vendor"] = {"status": r["status"], "value": r.get("outputs", [None])[0]}
    r = await call(obj, m("SdoDownload"), u16(0x6083), u8(0), ua.Variant(1234, ua.VariantType.UInt32))
    out["anonymous_download"] = r["status"]
    op1 = await secure_client(url, folder, "op1", "op1", "op1-secret")
    obj1 = op1.get_node(ua.NodeId(f"EtherCAT.Slaves.{slave}", ns))
    out["download"] = (await call(obj1, m("SdoDownload"), u16(0x6083), u8(0), ua.Variant(4321, ua.VariantType.UInt32)))[
        "status"
    ]
    r = await call(obj1, m("SdoUpload"), u16(0x6083), u8(0))
    out["read_back"] = r.get("outputs", [None])[0]
    out["mistyped"] = (await call(obj1, m("SdoDownload"), u16(0x6083), u8(0), ua.Variant("fast")))["status"]
    out["too_big"] = (
        await call(obj1, m("SdoDownload"), u16(0x605A), u8(0), ua.Variant(70000, ua.VariantType.Int32))
    )["status"]
    state_var = op1.get_node(ua.NodeId(f"EtherCAT.Slaves.{slave}.EtherCATState", ns))
    out["to_preop"] = (await call(obj1, m("RequestState"), ua.Variant("PREOP")))["status"]
    out["state_preop"] = await state_var.read_value()
    out["to_op"] = (await call(obj1, m("RequestState"), ua.Variant("OP")))["status"]
    out["state_op"] = await state_var.read_value()
    out["bad_state"] = (await call(obj1, m("RequestState"), ua.Variant("RUN")))["status"]
    await op1.disconnect()
    await anon.disconnect()
    return out


async def axis(url, folder, n):
    out = {}
    anon = Client(url=url, timeout=10)
    await anon.connect()
    ns = await anon.get_namespace_index(NAMESPACE)
    node = lambda c, name="": c.get_node(ua.NodeId(f"EtherCAT.Axes.{n}{name}", ns))  # noqa: E731
    method = lambda name: ua.NodeId(f"EtherCAT.Axes.{n}.{name}", ns)  # noqa: E731
    out["anonymous_enable"] = (await call(node(anon), method("Enable")))["status"]
    op1 = await secure_client(url, folder, "op1", "op1", "op1-secret")
    for step, args in [("Disable", []), ("Enable", []), ("SetMode", [ua.Variant(9, ua.VariantType.SByte)])]:
        r = await call(node(op1), method(step), *args)
        out[step] = {"status": r["status"], "state": (r.get("outputs") or [None])[0]}
        # The variable shows the newest input frame the host has; the
        # command's answer, the chip's newer view: a frame or two apart.
        out[step]["read"] = await read_back(op1, node(op1, ".State").nodeid, out[step]["state"], 1.0)
        out[step]["statusword"] = await node(op1, ".Statusword").read_value()
    out["bad_mode"] = (await call(node(op1), method("SetMode"), ua.Variant(9, ua.VariantType.Int32)))["status"]
    await op1.disconnect()
    await anon.disconnect()
    return out


async def read_aged(client, node_id, max_age_ms):
    params = ua.ReadParameters()
    params.MaxAge = max_age_ms
    rv = ua.ReadValueId()
    rv.NodeId = node_id
    rv.AttributeId = ua.AttributeIds.Value
    params.NodesToRead = [rv]
    dv = (await client.uaclient.read(params))[0]
    return dv.Value.Value if dv.StatusCode.is_good() else dv.StatusCode.name


async def dictionary(url, folder, slave, entry):
    out = {}
    anon = Client(url=url, timeout=10)
    await anon.connect()
    ns = await anon.get_namespace_index(NAMESPACE)
    node_id = ua.NodeId(f"EtherCAT.Slaves.{slave}.od.{entry}", ns)
    # The daemon reads the dictionary in the background after bring-up.
    end = time.time() + 20
    while True:
        try:
            out["display"] = (await anon.get_node(node_id).read_display_name()).Text
            break
        except ua.UaStatusCodeError:
            if time.time() > end:
                raise
            await asyncio.sleep(0.2)
    out["data_type"] = (await anon.get_node(node_id).read_data_type()).Identifier
    out["read"] = await read_aged(anon, node_id, 0)
    out["anonymous_write"] = await write_diagnosed(anon, node_id, ua.Variant(777, ua.VariantType.UInt32))
    op1 = await secure_client(url, folder, "op1", "op1", "op1-secret")
    out["op1_write"] = await write_diagnosed(op1, node_id, ua.Variant(999, ua.VariantType.UInt32))
    out["read_fresh"] = await read_aged(op1, node_id, 0)
    out["op1_write_again"] = await write_diagnosed(op1, node_id, ua.Variant(1000, ua.VariantType.UInt32))
    out["read_aged"] = await read_aged(op1, node_id, 60000)
    out["read_now"] = await read_aged(op1, node_id, 0)
    out["too_big"] = await write_diagnosed(op1, node_id, ua.Variant(-1, ua.VariantType.Int64))
    for name in ("SerialNumber", "SoftwareRevision"):
        out[name] = await read_aged(op1, ua.NodeId(f"EtherCAT.Slaves.{slave}.{name}", ns), 0)
    await op1.disconnect()
    await anon.disconnect()
    return out


async def connect(url, folder, name, policy, user=None, password=None):
    try:
        client = await secure_client(url, folder, name, user, password, policy)
    except Exception as e:  # noqa: BLE001 - any refusal is the answer
        return {"ok": False, "error": status_of(e)}
    try:
        ns = await client.get_namespace_index(NAMESPACE)
        out_vars = []
        await variables_under(client.get_node(ua.NodeId("EtherCAT.Slaves", ns)), out_vars)
        outputs = [v for v in out_vars if ".out." in str(v.Identifier)]
        level = await client.get_node(outputs[0]).read_attribute(ua.AttributeIds.UserAccessLevel)
        writable = bool(level.Value.Value & ua.AccessLevel.CurrentWrite.mask)
        return {"ok": True, "error": None, "role_write": writable}
    finally:
        await client.disconnect()


async def main(url, command, args):
    if command == "makecert":
        print(json.dumps(await makecert(args[0], args[1])), flush=True)
        return
    if command in ("writes", "methods", "connect", "axis", "dictionary"):
        run = {"writes": writes, "methods": methods, "connect": connect, "axis": axis, "dictionary": dictionary}[
            command
        ]
        print(json.dumps(await run(url, *args), default=str), flush=True)
        return
    if command == "load":
        result = await load(url, int(args[0]), int(args[1]), float(args[2]), float(args[3]))
        print(json.dumps(result), flush=True)
        return
    async with Client(url=url, timeout=10) as client:
        ns = await client.get_namespace_index(NAMESPACE)
        if command == "browse":
            result = await browse(client, ns)
        elif command == "events":
            result = await events(client, float(args[0]), float(args[1]))
        elif command == "subscribe":
            result = await subscribe(client, ns, float(args[0]), float(args[1]), args[2:])
        else:
            raise SystemExit(f"unknown command {command}")
    print(json.dumps(result, default=str), flush=True)


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], sys.argv[3:]))
