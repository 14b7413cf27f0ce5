//! Feeds arbitrary bytes to both packet decoders with every check type, and
//! parses whatever decodes. Run: `cargo +nightly fuzz run decode_packet`
//! from `wire/` (needs `cargo install cargo-fuzz`).
#![no_main]

use ecmxf_wire::payload::sdo::SdoGetReply;
use ecmxf_wire::{decode_command, decode_response, CheckType};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for check in CheckType::ALL {
        if let Ok(p) = decode_command(data, check) {
            let _ = p.parse();
        }
        if let Ok(p) = decode_response(data, check) {
            let _ = p.reply::<SdoGetReply>();
        }
    }
});
