// A gRPC client nobody here wrote the transport of: grpc-js with
// proto-loader, default channel options, the API loaded from proto/ alone.
// Calls one method of every ecmxf.v1 service (and gRPC health) over the
// daemon's Unix socket and prints, as one JSON object, what each answered;
// then an SDO upload of a missing object, with its google.rpc.Status
// details decoded from proto/google/rpc (tests/tests/grpc_js.rs checks it).
//
//   node grpc_client.js TARGET PROTO_DIR
//
// TARGET is a grpc-js target: unix:PATH or unix:///PATH.

"use strict";

const path = require("path");
const grpc = require("@grpc/grpc-js");
const protoLoader = require("@grpc/proto-loader");
const protobuf = require("protobufjs");

const [target, protoDir] = process.argv.slice(2);
if (!target || !protoDir) {
  console.error("usage: node grpc_client.js TARGET PROTO_DIR");
  process.exit(2);
}

const files = ["common", "master", "sdo", "pdo", "cia402", "admin", "peripherals"].map(
  (f) => `ecmxf/v1/${f}.proto`,
);
const loaded = protoLoader.loadSync(files, {
  includeDirs: [protoDir],
  keepCase: true,
  longs: String,
  enums: String,
  defaults: true,
});
const v1 = grpc.loadPackageDefinition(loaded).ecmxf.v1;
const credentials = grpc.credentials.createInsecure();
const clients = {};
for (const service of [
  "Master", "Slaves", "State", "ProcessData", "Sdo", "Sii", "Foe", "Registers", "Diagnostics", "Cia402",
  "Peripherals",
]) {
  // No options: what a first client writes.
  clients[service] = new v1[service](target, credentials);
}

// One unary call, settled as {ok, value} or {ok: false, code, details}.
function unary(service, method, request) {
  return new Promise((resolve) => {
    clients[service][method](request, { deadline: Date.now() + 10000 }, (err, value) => {
      if (err) {
        resolve({ ok: false, code: grpc.status[err.code], message: err.details, metadata: err.metadata });
      } else {
        resolve({ ok: true, value });
      }
    });
  });
}

// The first `count` messages of a server stream, then a cancel.
function firstOf(service, method, request, count) {
  return new Promise((resolve) => {
    const got = [];
    const call = clients[service][method](request);
    call.on("data", (m) => {
      got.push(m);
      if (got.length === count) {
        call.cancel();
        resolve({ ok: true, value: got });
      }
    });
    call.on("error", (err) => {
      if (got.length < count) {
        resolve({ ok: false, code: grpc.status[err.code], message: err.details });
      }
    });
  });
}

// The google.rpc.Status of an error, decoded with proto/google/rpc only.
function richStatus(metadata) {
  const raw = metadata.get("grpc-status-details-bin")[0];
  if (!raw) {
    return null;
  }
  const root = new protobuf.Root();
  root.resolvePath = (_origin, target) =>
    target.startsWith("google/protobuf/") ? target : path.join(protoDir, target);
  root.loadSync(["google/rpc/status.proto", "google/rpc/error_details.proto"]);
  root.resolveAll();
  const Status = root.lookupType("google.rpc.Status");
  const status = Status.toObject(Status.decode(raw), { defaults: true });
  status.details = status.details.map((any) => {
    const type = any.type_url.split("/").pop();
    const T = root.lookupType(type);
    return { type, value: T.toObject(T.decode(any.value), { defaults: true }) };
  });
  return status;
}

async function main() {
  const calls = {
    "Master.GetInfo": unary("Master", "GetInfo", {}),
    "Master.GetStatus": unary("Master", "GetStatus", {}),
    "Slaves.ListSlaves": unary("Slaves", "ListSlaves", {}),
    "State.GetState": unary("State", "GetState", {}),
    "ProcessData.GetLayout": unary("ProcessData", "GetLayout", {}),
    "ProcessData.StreamInputs": firstOf("ProcessData", "StreamInputs", {}, 3),
    "Sdo.Upload": unary("Sdo", "Upload", { slave: 1, index: 0x1018, subindex: 1 }),
    "Sii.Read": unary("Sii", "Read", { slave: 1, word: 8, count: 2 }),
    "Foe.Read": firstOf("Foe", "Read", { slave: 99, name: "x" }, 1),
    "Registers.ReadRegisters": unary("Registers", "ReadRegisters", { slave: 0, address: 0, length: 2 }),
    "Diagnostics.GetCounters": unary("Diagnostics", "GetCounters", {}),
    "Cia402.ListAxes": unary("Cia402", "ListAxes", {}),
    "Peripherals.GetGpio": unary("Peripherals", "GetGpio", {}),
  };
  const out = {};
  for (const [name, call] of Object.entries(calls)) {
    const r = await call;
    // Enough of each answer to compare, not the whole message.
    out[name] = r.ok ? { ok: true, value: JSON.parse(JSON.stringify(r.value)) } : { ok: false, code: r.code, message: r.message };
  }
  const missing = await unary("Sdo", "Upload", { slave: 1, index: 0x2fff, subindex: 0 });
  out.missing = { code: missing.code, message: missing.message, status: missing.ok ? null : richStatus(missing.metadata) };
  const health = new (grpc.loadPackageDefinition(
    protoLoader.loadSync("health.proto", { includeDirs: [path.join(__dirname)], enums: String }),
  ).grpc.health.v1.Health)(target, credentials);
  out.health = await new Promise((resolve) =>
    health.Check({ service: "" }, (err, r) => resolve(err ? { ok: false, code: grpc.status[err.code] } : r)),
  );
  process.stdout.write(JSON.stringify(out) + "\n");
  for (const c of Object.values(clients)) {
    c.close();
  }
  health.close();
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
