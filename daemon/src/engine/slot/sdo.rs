//! SDO upload and download (v049 SDO_REQ 10; the result with SDO_GET 11,
//! an abort's code with SDO_ABORT_CODE_GET 69). An upload is a read: sent
//! once, its SDO_GET is the poll. A download runs exactly once: guarded.

use ecmxf_wire::payload::sdo::{
    SDO_REQ_HEADER_LEN, SdoAbortCode, SdoAbortCodeGet, SdoAccess, SdoGet, SdoGetReply, SdoRequest,
};

use super::handler::{Cx, Fetch, Handler, Next, fetched_or_call, fill};
use crate::engine::error::EngineError;
use crate::link::Link;
use crate::port::PortError;

/// SDO timeout given to the chip, us.
const SDO_TIMEOUT_US: u32 = 1_000_000;

/// An SDO upload or download.
#[derive(Debug)]
pub(super) struct Sdo {
    slave: u8,
    index: u16,
    subindex: u8,
    complete: bool,
    /// A download (its bytes are the request's).
    write: bool,
}

impl Sdo {
    /// An upload, or with `write` a download of the request's bytes.
    pub(super) fn new(slave: u8, index: u16, subindex: u8, complete: bool, write: bool) -> Self {
        Self { slave, index, subindex, complete, write }
    }

    fn request<'d>(&self, access: SdoAccess<'d>) -> SdoRequest<'d> {
        let (slave, index, subindex, complete_access) = (self.slave, self.index, self.subindex, self.complete);
        SdoRequest { slave, index, subindex, complete_access, timeout_us: SDO_TIMEOUT_US, access }
    }
}

impl Handler for Sdo {
    fn start<L: Link>(&mut self, cx: &mut Cx<'_, L>) -> Result<Next, PortError> {
        let data_size = cx.port.data_size();
        if !self.write {
            let access = SdoAccess::Read { max_len: (data_size - SDO_REQ_HEADER_LEN) as u16 };
            return cx.read(&self.request(access));
        }
        let data = cx.request.payload();
        if data.len() + SDO_REQ_HEADER_LEN > data_size {
            let field = "data";
            let reason = format!("{} bytes do not fit one {data_size}-byte data section", data.len());
            return Ok(Next::Done(Err(EngineError::BadArgument { field, reason })));
        }
        cx.start(&self.request(SdoAccess::Write(data)))
    }

    fn fetch(&self) -> Option<Fetch> {
        (!self.write).then_some(Fetch::Sdo)
    }

    fn ended<L: Link>(&mut self, cx: &mut Cx<'_, L>, failed: bool) -> Result<Next, PortError> {
        let (slave, index, subindex) = (self.slave, self.index, self.subindex);
        if failed {
            let answer = cx.port.call(&SdoAbortCodeGet)?.answer_to(&SdoAbortCodeGet);
            let code = answer.map_or(SdoAbortCode::GENERAL, |r| r.0);
            return Ok(Next::Done(Err(EngineError::SdoAbort { slave, index, subindex, code })));
        }
        if self.write {
            return Ok(Next::Done(Ok(Vec::new())));
        }
        let a = fetched_or_call(cx.port, cx.fetched, &SdoGet)?;
        // SDO_GET's return value is the read's error code: data with a
        // nonzero code is not this read's value.
        Ok(Next::Done(match a.answer_to(&SdoGet) {
            Ok(SdoGetReply { status: 0, data }) => Ok(fill(cx.buffer, &[data])),
            Err(error) => Err(EngineError::BadAnswer { what: cx.what(), error }),
            Ok(SdoGetReply { status: code, .. }) => {
                let what = cx.what();
                Err(EngineError::Failed(format!("{what}: SDO_GET reports error code {code}")))
            }
        }))
    }
}
