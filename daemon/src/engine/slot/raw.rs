//! One raw EtherCAT datagram (v049 RAW_ECAT_FUNC_REQ 137, the result with
//! RAW_ECAT_FUNC_GET 138). A datagram may write: it runs exactly once
//! (guarded). The reply is the working counter (u16, little-endian)
//! followed by the returned data.

use ecmxf_wire::payload::raw::{DatagramHead, RAW_HEADER_LEN, RawGet, RawRequest};

use super::handler::{Cx, Handler, Next, fill};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// A datagram (its bytes are the request's).
#[derive(Debug)]
pub(super) struct Raw {
    head: DatagramHead,
}

impl Raw {
    pub(super) fn new(head: DatagramHead) -> Self {
        Self { head }
    }
}

impl Handler for Raw {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let data_size = cx.port.data_size();
        let data = cx.request.payload();
        if data.len() + RAW_HEADER_LEN > data_size {
            let reason = format!("{} bytes do not fit one {data_size}-byte data section", data.len());
            return Ok(Next::Done(Err(EngineError::BadArgument { field: "data", reason })));
        }
        cx.start(&RawRequest { head: self.head, data })
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        if failed {
            return Ok(Next::Done(Err(EngineError::Failed(cx.what()))));
        }
        Ok(Next::Done(match cx.port.call(&RawGet)?.answer_to(&RawGet) {
            Ok(r) => Ok(fill(cx.buffer, &[&r.working_counter.to_le_bytes(), r.data])),
            Err(error) => Err(EngineError::BadAnswer { what: cx.what(), error }),
        }))
    }
}
