//! Encode + check word + decode of whole packets, CRC-32, at the default
//! (144-byte) and the largest (1440-byte) packet size. The payload is a
//! PDO_DATA_FIFO_OP filling the data section, the packet the daemon sends
//! most. Run with `cargo bench -p ecmxf-wire`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ecmxf_wire::payload::pdo::{FifoOpFlags, PdoFifoOp, PdoFifoReply};
use ecmxf_wire::{
    CheckType, CommandHeader, ResponseHeader, decode_command, decode_response, encode_reply, encode_request,
};

fn round_trip(c: &mut Criterion) {
    let mut group = c.benchmark_group("packet_crc32");
    for packet_len in [144usize, 1440] {
        let data_size = packet_len - 32;
        let frames: Vec<u8> = (0..data_size).map(|i| i as u8).collect();
        let mut buf = vec![0u8; packet_len];
        group.throughput(Throughput::Bytes(packet_len as u64));

        group.bench_with_input(BenchmarkId::new("command_encode_decode", packet_len), &packet_len, |b, _| {
            b.iter(|| {
                let req =
                    PdoFifoOp { op: FifoOpFlags::WRITE | FifoOpFlags::READ, frames: 1, outputs: black_box(&frames) };
                encode_request(&req, CommandHeader::new(req_code(), 7), CheckType::Crc32, &mut buf).unwrap();
                let packet = decode_command(black_box(&buf), CheckType::Crc32).unwrap();
                black_box(packet.request::<PdoFifoOp>().unwrap());
            })
        });

        group.bench_with_input(BenchmarkId::new("response_encode_decode", packet_len), &packet_len, |b, _| {
            b.iter(|| {
                let reply = PdoFifoReply { op: FifoOpFlags::READ, inputs: black_box(&frames) };
                encode_reply(&reply, ResponseHeader::default(), CheckType::Crc32, &mut buf).unwrap();
                let packet = decode_response(black_box(&buf), CheckType::Crc32).unwrap();
                black_box(packet.reply::<PdoFifoReply>().unwrap());
            })
        });

        group.bench_with_input(BenchmarkId::new("check_word_only", packet_len), &packet_len, |b, _| {
            b.iter(|| black_box(CheckType::Crc32.compute(black_box(&buf[..packet_len - 8]))))
        });
    }
    group.finish();
}

fn req_code() -> ecmxf_wire::CommandCode {
    ecmxf_wire::CommandCode::PdoDataFifoOp
}

criterion_group!(benches, round_trip);
criterion_main!(benches);
