//! The servers' codec: tonic's prost codec, except that a request body that
//! is not a valid protobuf message is answered INVALID_ARGUMENT — the
//! caller sent it — where tonic answers INTERNAL, which the API reserves for
//! the daemon's and the chip's own failures (proto/README.md, "Errors").
//! Clients keep tonic's codec: a reply that does not decode is not the
//! caller's fault. Tested end to end (tests/tests/errors.rs): tonic builds
//! the decode buffer itself.

use std::marker::PhantomData;

use tonic::Status;
use tonic::codec::{BufferSettings, Codec, DecodeBuf, Decoder};
use tonic_prost::{ProstDecoder, ProstEncoder};

/// Encodes replies like tonic's `ProstCodec`; decodes requests with
/// [`RequestDecoder`].
#[derive(Debug, Clone)]
pub struct RequestCodec<T, U>(PhantomData<(T, U)>);

impl<T, U> Default for RequestCodec<T, U> {
    fn default() -> Self {
        Self(PhantomData)
    }
}

impl<T, U> Codec for RequestCodec<T, U>
where
    T: prost::Message + Send + 'static,
    U: prost::Message + Default + Send + 'static,
{
    type Encode = T;
    type Decode = U;
    type Encoder = ProstEncoder<T>;
    type Decoder = RequestDecoder<U>;

    fn encoder(&mut self) -> Self::Encoder {
        ProstEncoder::new(BufferSettings::default())
    }

    fn decoder(&mut self) -> Self::Decoder {
        RequestDecoder(ProstDecoder::new(BufferSettings::default()))
    }
}

/// Decodes one request message; a body that does not decode is
/// INVALID_ARGUMENT naming the message type and what was wrong.
#[derive(Debug, Clone, Default)]
pub struct RequestDecoder<U>(ProstDecoder<U>);

impl<U: prost::Message + Default> Decoder for RequestDecoder<U> {
    type Item = U;
    type Error = Status;

    fn decode(&mut self, buf: &mut DecodeBuf<'_>) -> Result<Option<U>, Status> {
        self.0.decode(buf).map_err(|e| {
            Status::invalid_argument(format!("the request is not a valid {}: {}", message_name::<U>(), e.message()))
        })
    }

    fn buffer_settings(&self) -> BufferSettings {
        self.0.buffer_settings()
    }
}

/// `ecmxf.v1.SdoReadRequest` for the Rust type `ecmxf_proto::v1::SdoReadRequest`.
fn message_name<U>() -> String {
    let rust = std::any::type_name::<U>();
    match rust.rsplit_once("::") {
        Some((_, name)) if rust.contains("::v1::") => format!("ecmxf.v1.{name}"),
        _ => rust.to_owned(),
    }
}
