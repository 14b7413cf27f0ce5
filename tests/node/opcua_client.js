// A second independent OPC UA client (node-opcua, from the npm registry) for
// tests/tests/opcua_node.rs: what tests/python/opcua_client.py does with
// asyncua, done by another stack, so a server bug one client tolerates is
// not hidden.
//
//     node opcua_client.js URL browse
//         The daemon's address space as JSON, in opcua_client.py's shape:
//         the master's variables, and per slave its properties and
//         variables and its Inputs/Outputs entries (browse name, display
//         name, data type, value, status, source time), plus what looked
//         odd to this client ("odd": a non-Good status of any attribute
//         read, a value whose type is not the variable's DataType, a
//         non-scalar variable, a failed browse).
//     node opcua_client.js URL subscribe SECONDS SAMPLING_MS NODE_ID...
//         One subscription with a monitored item per node (string node ids
//         of the daemon's namespace) at the sampling interval, for SECONDS:
//         "subscribed" once set up, then {"changes": [...], "revised": ...}
//         with each data change and the local time it arrived, and the
//         revised intervals.
//
// The last line of stdout is the JSON, with "odd", "endpoints" (the
// endpoint URLs GetEndpoints lists) and "client_warnings" (what node-opcua
// warned of, also written to stderr) in both. The client's PKI (its
// self-signed certificate, made even for SecurityPolicy None) is in
// $ECMXF_NODE_OPCUA_PKI, else in a temporary folder removed at exit, never
// under $HOME. node-opcua-client is found through NODE_PATH
// (target/node-opcua/node_modules, which .ci/run installs).

"use strict";

const fs = require("node:fs");
const os = require("node:os");
const path = require("node:path");
const util = require("node:util");

// Before node-opcua-client loads: it warns while loading.
const warnings = [];
const debug = require("node-opcua-debug");
const keep = (...args) => {
    // node-opcua passes where it logged from first.
    const where = args[0] && typeof args[0] === "object" && "filename" in args[0] ? args.shift() : null;
    const words = args.map((a) => (typeof a === "string" ? a : util.inspect(a))).join(" ");
    const text = where ? `${where.filename}:${where.callerline}: ${words}` : words;
    warnings.push(text);
    process.stderr.write(text + "\n");
};
debug.setWarningLogger(keep);
debug.setErrorLogger(keep);

const {
    AttributeIds,
    BrowseDirection,
    DataType,
    MessageSecurityMode,
    NodeClass,
    OPCUAClient,
    SecurityPolicy,
    TimestampsToReturn,
    VariantArrayType,
    browseAll,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

const NAMESPACE = "urn:ecmxf:ecmxfd";

// What looked odd to this client (see the top), for the caller to judge.
const odd = [];

// The PKI folder, and whether it is ours to remove.
function pkiFolder() {
    if (process.env.ECMXF_NODE_OPCUA_PKI) {
        return [process.env.ECMXF_NODE_OPCUA_PKI, false];
    }
    return [fs.mkdtempSync(path.join(os.tmpdir(), "ecmxf-node-opcua-")), true];
}

// 64-bit integers come as [high, low] words; JSON gets them exact.
function int64(v, signed) {
    const n = (BigInt(v[0] >>> 0) << 32n) | BigInt(v[1] >>> 0);
    return signed ? BigInt.asIntN(64, n) : n;
}

function plain(variant) {
    if (!variant || variant.value === null || variant.value === undefined) {
        return null;
    }
    const one = (x) => {
        switch (variant.dataType) {
            case DataType.Int64:
                return int64(x, true);
            case DataType.UInt64:
                return int64(x, false);
            case DataType.ByteString:
                return x === null ? null : Buffer.from(x).toString("hex");
            case DataType.LocalizedText:
                return x.text;
            case DataType.QualifiedName:
                return x.name;
            case DataType.DateTime:
                return x.getTime();
            case DataType.NodeId:
                return x.toString();
            default:
                return x;
        }
    };
    if (variant.arrayType !== VariantArrayType.Scalar) {
        return Array.from(variant.value, one);
    }
    return one(variant.value);
}

function stringify(value) {
    const text = JSON.stringify(value, (_k, v) => (typeof v === "bigint" ? `__bigint__${v}` : v));
    return text.replace(/"__bigint__(-?\d+)"/g, "$1");
}

function ms(date) {
    return date ? date.getTime() : null;
}

function nodeIdText(nodeId) {
    return nodeId.namespace === 0 ? Number(nodeId.value) : nodeId.toString();
}

async function children(session, nodeId) {
    const result = await browseAll(session, {
        nodeId,
        referenceTypeId: "HierarchicalReferences",
        includeSubtypes: true,
        browseDirection: BrowseDirection.Forward,
        nodeClassMask: 0,
        resultMask: 0x3f,
    });
    if (result.statusCode.name !== "Good") {
        odd.push(`browse ${nodeId.toString()}: ${result.statusCode.toString()}`);
    }
    return result.references || [];
}

const ATTRIBUTES = [
    ["value", AttributeIds.Value],
    ["data_type", AttributeIds.DataType],
    ["display", AttributeIds.DisplayName],
    ["description", AttributeIds.Description],
    ["value_rank", AttributeIds.ValueRank],
    ["access_level", AttributeIds.AccessLevel],
    ["user_access_level", AttributeIds.UserAccessLevel],
];

async function variable(session, nodeId) {
    const read = await session.read(
        ATTRIBUTES.map(([, attributeId]) => ({ nodeId, attributeId })),
        0,
    );
    const at = Object.fromEntries(ATTRIBUTES.map(([name], i) => [name, read[i]]));
    const id = nodeId.toString();
    for (const [name] of ATTRIBUTES) {
        // The value's status is the test's to judge (it says when data
        // does not flow); any other attribute must read.
        if (name !== "value" && at[name].statusCode.name !== "Good") {
            odd.push(`${id} ${name}: ${at[name].statusCode.toString()}`);
        }
    }
    const dv = at.value;
    const dataType = at.data_type.value.value;
    const valueRank = at.value_rank.value.value;
    const accessLevel = at.access_level.value.value;
    const userAccessLevel = at.user_access_level.value.value;
    if (dv.value && dv.value.dataType !== DataType.Null && dataType && dataType.namespace === 0) {
        if (dv.value.dataType !== Number(dataType.value)) {
            odd.push(`${id}: value is ${DataType[dv.value.dataType]}, DataType attribute says i=${dataType.value}`);
        }
        if (dv.value.arrayType !== VariantArrayType.Scalar) {
            odd.push(`${id}: value is an array (${VariantArrayType[dv.value.arrayType]})`);
        }
    }
    if (valueRank !== -1) {
        odd.push(`${id}: ValueRank ${valueRank}, not -1 (scalar)`);
    }
    return {
        display: at.display.value.value ? at.display.value.value.text : null,
        data_type: dataType ? nodeIdText(dataType) : null,
        value: plain(dv.value),
        variant_type: dv.value ? dv.value.dataType : null,
        status: dv.statusCode.name,
        source_ms: ms(dv.sourceTimestamp),
        description: at.description.value.value ? at.description.value.value.text : null,
        access_level: accessLevel,
        user_access_level: userAccessLevel,
    };
}

async function browse(session, ns) {
    const root = `ns=${ns};s=EtherCAT`;
    const out = { master: {}, slaves: [] };
    let slavesFolder = null;
    for (const ref of await children(session, root)) {
        const name = ref.browseName.name;
        if (ref.nodeClass === NodeClass.Variable) {
            out.master[name] = (await variable(session, ref.nodeId)).value;
        } else if (name === "Slaves") {
            slavesFolder = ref.nodeId;
        }
    }
    if (slavesFolder === null) {
        throw new Error("no Slaves under the EtherCAT object");
    }
    for (const slave of await children(session, slavesFolder)) {
        const entry = { display: slave.displayName.text, node_id: slave.nodeId.value, entries: [] };
        for (const child of await children(session, slave.nodeId)) {
            const name = child.browseName.name;
            if (child.nodeClass === NodeClass.Variable) {
                entry[name] = (await variable(session, child.nodeId)).value;
                continue;
            }
            // A method's children are its InputArguments and
            // OutputArguments: Argument arrays the specification names.
            if (child.nodeClass === NodeClass.Method) {
                (entry.methods = entry.methods || []).push(name);
                continue;
            }
            // The process data; the Dictionary folder is read from the
            // device, entry by entry, not browsed here.
            if (name !== "Inputs" && name !== "Outputs") {
                (entry.folders = entry.folders || []).push(name);
                continue;
            }
            for (const v of await children(session, child.nodeId)) {
                const described = await variable(session, v.nodeId);
                described.folder = name;
                described.browse_name = v.browseName.name;
                described.node_id = v.nodeId.value;
                if (v.browseName.namespaceIndex !== ns) {
                    odd.push(`${v.nodeId.toString()}: browse name in namespace ${v.browseName.namespaceIndex}`);
                }
                entry.entries.push(described);
            }
        }
        out.slaves.push(entry);
    }
    return out;
}

async function subscribe(session, ns, seconds, samplingMs, ids) {
    const subscription = await session.createSubscription2({
        requestedPublishingInterval: samplingMs,
        requestedLifetimeCount: 100,
        requestedMaxKeepAliveCount: 10,
        maxNotificationsPerPublish: 0,
        publishingEnabled: true,
        priority: 1,
    });
    const changes = [];
    const revised = { publishing_interval_ms: subscription.publishingInterval, sampling_interval_ms: {} };
    for (const id of ids) {
        const item = await subscription.monitor(
            { nodeId: `ns=${ns};s=${id}`, attributeId: AttributeIds.Value },
            { samplingInterval: samplingMs, discardOldest: true, queueSize: 10 },
            TimestampsToReturn.Both,
        );
        if (item.statusCode && item.statusCode.name !== "Good") {
            odd.push(`monitor ${id}: ${item.statusCode.toString()}`);
        }
        revised.sampling_interval_ms[id] = item.monitoringParameters.samplingInterval;
        item.on("changed", (dv) => {
            changes.push({
                node_id: id,
                value: plain(dv.value),
                status: dv.statusCode.name,
                source_ms: ms(dv.sourceTimestamp),
                arrived_ms: Date.now(),
            });
        });
        item.on("err", (message) => odd.push(`monitor ${id}: ${message}`));
    }
    // Ready: the caller starts changing things now.
    process.stdout.write("subscribed\n");
    await new Promise((resolve) => setTimeout(resolve, seconds * 1000));
    await subscription.terminate();
    return { changes, revised };
}

async function main(url, command, args) {
    const [pki, ours] = pkiFolder();
    const client = OPCUAClient.create({
        applicationName: "ecmxf-e2e-node-opcua",
        securityMode: MessageSecurityMode.None,
        securityPolicy: SecurityPolicy.None,
        // GetEndpoints lists the URL of the server's listener behind the
        // daemon's gate (docs/opcua.md, Security), not the one dialled:
        // node-opcua would refuse to connect, asyncua does not check. The
        // listed URLs are in the output, for a test to hold them to it.
        endpointMustExist: false,
        // One attempt: a daemon that is not there is a failure, not a wait.
        connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
        requestedSessionTimeout: 20000,
        clientCertificateManager: new OPCUACertificateManager({
            rootFolder: pki,
            automaticallyAcceptUnknownCertificate: true,
        }),
    });
    let result;
    let endpoints;
    try {
        await client.connect(url);
        endpoints = (await client.getEndpoints()).map((e) => e.endpointUrl);
        const session = await client.createSession();
        try {
            const namespaces = await session.readNamespaceArray();
            const ns = namespaces.indexOf(NAMESPACE);
            if (ns < 0) {
                throw new Error(`namespace ${NAMESPACE} not in ${JSON.stringify(namespaces)}`);
            }
            if (command === "browse") {
                result = await browse(session, ns);
            } else if (command === "subscribe") {
                result = await subscribe(session, ns, Number(args[0]), Number(args[1]), args.slice(2));
            } else {
                throw new Error(`unknown command ${command}`);
            }
        } finally {
            await session.close();
        }
    } finally {
        await client.disconnect();
        if (ours) {
            fs.rmSync(pki, { recursive: true, force: true });
        }
    }
    result.endpoints = endpoints;
    result.odd = odd;
    result.client_warnings = warnings;
    process.stdout.write(stringify(result) + "\n");
}

// A server that stops answering fails the run rather than hanging it.
const seconds = process.argv[3] === "subscribe" ? Number(process.argv[4]) : 0;
setTimeout(() => {
    process.stderr.write("no answer within the time limit\n");
    process.exit(2);
}, (seconds + 30) * 1000).unref();

main(process.argv[2], process.argv[3], process.argv.slice(4)).then(
    () => process.exit(0),
    (e) => {
        process.stderr.write(`${e.stack || e}\n`);
        process.exit(1);
    },
);
