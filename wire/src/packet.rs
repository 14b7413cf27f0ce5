//! Whole packets: encode into a caller's buffer, decode and validate.
//!
//! The buffer's length IS the packet length (64..=1440): both sides agree on
//! the data-section size, so a buffer of the agreed size is the only input
//! that makes sense, and a wrong size is an error, not a guess.
//!
//! Encoding zeroes the unused part of the data section, because the check word
//! covers the whole section (v049 ECM_CMD_CRC_TYPE_SET; docs/protocol.md §4).

use crate::check::{CHECK_NOT_READY, CheckType};
use crate::error::{DecodeError, EncodeError, PayloadError};
use crate::framing::{END_WORD, PacketLayout};
use crate::header::{CommandHeader, HEADER_LEN, ResponseHeader};
use crate::payload::pdo::{PDO_CONFIG_LEN, PdoConfigForm};
use crate::payload::{AnyRequest, FromAnswer, Reply, ReplyFields, Request, RequestFields};

fn layout_of(len: usize) -> Result<PacketLayout, EncodeError> {
    PacketLayout::from_packet_len(len).ok_or(EncodeError::PacketLength { len })
}

/// Splits a packet buffer into header, data section and trailer.
fn split_mut(buf: &mut [u8], layout: PacketLayout) -> (&mut [u8; HEADER_LEN], &mut [u8]) {
    let (head, rest) = buf.split_at_mut(HEADER_LEN);
    let head: &mut [u8; HEADER_LEN] = head.try_into().expect("split at HEADER_LEN");
    (head, &mut rest[..layout.data_size()])
}

/// Writes the check word and end word after the header and data section.
fn seal(buf: &mut [u8], layout: PacketLayout, check: CheckType) {
    let at = layout.check_offset();
    let word = check.compute(&buf[..at]);
    buf[at..at + 4].copy_from_slice(&word.to_le_bytes());
    buf[at + 4..at + 8].copy_from_slice(&END_WORD.to_le_bytes());
}

/// Encodes a typed request. `base` supplies what the request does not: index,
/// control byte, interrupt clears, header GPIO; the code, parameter, command
/// data and data length come from the request. Returns the header sent.
pub fn encode_request<'a, R: Request<'a>>(
    request: &R,
    base: CommandHeader,
    check: CheckType,
    buf: &mut [u8],
) -> Result<CommandHeader, EncodeError> {
    let layout = layout_of(buf.len())?;
    let (head, data) = split_mut(buf, layout);
    data.fill(0);
    let RequestFields { parameter, param, data_len, options } = request.encode(data)?;
    let header = CommandHeader { code: R::CODE, parameter, param, data_len, options: base.options | options, ..base };
    header.encode(head);
    seal(buf, layout, check);
    Ok(header)
}

/// Encodes a header and raw data section bytes (the rest of the section is
/// zeroed). For commands this crate has no type for, and for tests.
pub fn encode_command(
    header: &CommandHeader,
    data: &[u8],
    check: CheckType,
    buf: &mut [u8],
) -> Result<(), EncodeError> {
    let layout = layout_of(buf.len())?;
    if data.len() > layout.data_size() {
        return Err(EncodeError::PayloadTooLarge { needed: data.len(), capacity: layout.data_size() });
    }
    let (head, section) = split_mut(buf, layout);
    header.encode(head);
    section[..data.len()].copy_from_slice(data);
    section[data.len()..].fill(0);
    seal(buf, layout, check);
    Ok(())
}

/// Encodes a typed reply (the chip's side). `base` supplies the status part
/// of the header; the code, return value and data length come from the reply.
pub fn encode_reply<'a, R: Reply<'a>>(
    reply: &R,
    base: ResponseHeader,
    check: CheckType,
    buf: &mut [u8],
) -> Result<ResponseHeader, EncodeError> {
    let layout = layout_of(buf.len())?;
    let (head, data) = split_mut(buf, layout);
    data.fill(0);
    let ReplyFields { value, data_len } = reply.encode(data)?;
    let header = ResponseHeader { code: R::CODE, return_value: value, data_len, ..base };
    header.encode(head);
    seal(buf, layout, check);
    Ok(header)
}

/// Encodes a response header and raw data bytes (the rest zeroed).
pub fn encode_response(
    header: &ResponseHeader,
    data: &[u8],
    check: CheckType,
    buf: &mut [u8],
) -> Result<(), EncodeError> {
    let layout = layout_of(buf.len())?;
    if data.len() > layout.data_size() {
        return Err(EncodeError::PayloadTooLarge { needed: data.len(), capacity: layout.data_size() });
    }
    let (head, section) = split_mut(buf, layout);
    header.encode(head);
    section[..data.len()].copy_from_slice(data);
    section[data.len()..].fill(0);
    seal(buf, layout, check);
    Ok(())
}

/// Validates framing and the check word; returns the header bytes and the
/// data section.
fn validate(buf: &[u8], check: CheckType) -> Result<(&[u8; HEADER_LEN], &[u8]), DecodeError> {
    let layout = PacketLayout::from_packet_len(buf.len()).ok_or(DecodeError::PacketLength { len: buf.len() })?;
    let at = layout.check_offset();
    let word = |i: usize| u32::from_le_bytes([buf[i], buf[i + 1], buf[i + 2], buf[i + 3]]);
    let found = word(at);
    if found == CHECK_NOT_READY {
        return Err(DecodeError::ChipNotReady);
    }
    let end = word(at + 4);
    if end != END_WORD {
        return Err(DecodeError::EndWord { found: end });
    }
    // Start word next so a misaligned stream reports framing, not CRC.
    let start = word(0);
    if start != crate::framing::START_WORD {
        return Err(DecodeError::StartWord { found: start });
    }
    let expected = check.compute(&buf[..at]);
    if found != expected {
        return Err(DecodeError::CheckWord { check_type: check, expected, found });
    }
    let head: &[u8; HEADER_LEN] = buf[..HEADER_LEN].try_into().expect("length checked");
    Ok((head, &buf[HEADER_LEN..at]))
}

/// A validated command packet (the chip's view).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandPacket<'a> {
    /// The header.
    pub header: CommandHeader,
    /// The whole data section; how much of it is valid depends on the command.
    pub data_section: &'a [u8],
}

impl<'a> CommandPacket<'a> {
    /// The per-command header fields.
    pub fn fields(&self) -> RequestFields {
        RequestFields {
            parameter: self.header.parameter,
            param: self.header.param,
            data_len: self.header.data_len,
            options: self.header.options,
        }
    }

    /// Parses the payload as `R`.
    pub fn request<R: Request<'a>>(&self) -> Result<R, PayloadError> {
        if self.header.code != R::CODE {
            return Err(PayloadError::WrongCommand { expected: R::CODE, found: self.header.code });
        }
        R::decode(&self.fields(), self.data_section)
    }

    /// Parses the payload by its code, holding it to the data length v049
    /// gives the command's layout (what ecmxfd writes).
    pub fn parse(&self) -> Result<AnyRequest<'a>, PayloadError> {
        AnyRequest::decode(self.header.code, &self.fields(), self.data_section)
    }

    /// Parses the payload by its code, reading a fixed layout's fields from
    /// their places whatever length the header declares, as the chip does
    /// with the vendor's driver: DCSYNC declared with 0 bytes and a filled
    /// 16-byte layout (a chip that refused it would never have worked with
    /// that driver; docs/protocol.md §11). Returns the request and, when the declared
    /// length differs from the layout's, the [`PayloadError::DataLength`]
    /// passed over, for the caller to count or refuse.
    pub fn parse_declared_len_aside(&self) -> Result<(AnyRequest<'a>, Option<PayloadError>), PayloadError> {
        match self.parse() {
            Ok(req) => {
                // The vendor driver's PDO-configuration forms are read as
                // laid out, and are still not v049's length.
                let v049 = match &req {
                    AnyRequest::PdoConfigSet(c) if c.form != PdoConfigForm::Manual => Some(PDO_CONFIG_LEN as u16),
                    AnyRequest::PdoConfigReq(r) if r.form != PdoConfigForm::Manual => Some(4),
                    _ => None,
                };
                let found = self.header.data_len;
                let mismatch =
                    v049.map(|expected| PayloadError::DataLength { command: self.header.code, expected, found });
                Ok((req, mismatch))
            }
            Err(mismatch @ PayloadError::DataLength { expected, .. }) => {
                let fields = RequestFields { data_len: expected, ..self.fields() };
                let req = AnyRequest::decode(self.header.code, &fields, self.data_section)?;
                Ok((req, Some(mismatch)))
            }
            Err(e) => Err(e),
        }
    }
}

/// A validated response packet (the host's view).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResponsePacket<'a> {
    /// The header.
    pub header: ResponseHeader,
    /// The valid part of the data section (header's data length).
    pub data: &'a [u8],
    /// The whole data section.
    pub data_section: &'a [u8],
}

impl<'a> ResponsePacket<'a> {
    /// The per-command header fields.
    pub fn fields(&self) -> ReplyFields {
        ReplyFields { value: self.header.return_value, data_len: self.header.data_len }
    }

    /// Reads it as the answer to `request`, the type its request names.
    pub fn answer_to<'q, R: Request<'q>>(&self, request: &R) -> Result<R::Answer<'a>, PayloadError> {
        read_answer(request, &self.header, self.data)
    }

    /// Parses the payload as `R`, refusing NOPs and other commands' answers.
    pub fn reply<R: Reply<'a>>(&self) -> Result<R, PayloadError> {
        if self.header.is_nop() {
            return Err(PayloadError::Nop);
        }
        if self.header.code != R::CODE {
            return Err(PayloadError::WrongCommand { expected: R::CODE, found: self.header.code });
        }
        R::decode(&self.fields(), self.data)
    }
}

/// Reads the answer to `request` from a response's header and valid data,
/// as the type the request names ([`Request::Answer`]); refuses NOPs and
/// other commands' answers, so an answer is never read as another's.
pub fn read_answer<'q, 'r, R: Request<'q>>(
    request: &R,
    header: &ResponseHeader,
    data: &'r [u8],
) -> Result<R::Answer<'r>, PayloadError> {
    if header.is_nop() {
        return Err(PayloadError::Nop);
    }
    if header.code != R::CODE {
        return Err(PayloadError::WrongCommand { expected: R::CODE, found: header.code });
    }
    let fields = ReplyFields { value: header.return_value, data_len: header.data_len };
    R::Answer::from_answer(request, &fields, data)
}

/// Decodes and validates a command packet: length, end word, start word,
/// check word of type `check`.
pub fn decode_command(buf: &[u8], check: CheckType) -> Result<CommandPacket<'_>, DecodeError> {
    let (head, data_section) = validate(buf, check)?;
    Ok(CommandPacket { header: CommandHeader::decode(head)?, data_section })
}

/// Decodes and validates a response packet: length, "not ready" marker, end
/// word, start word, check word of type `check`, data length within the
/// section.
pub fn decode_response(buf: &[u8], check: CheckType) -> Result<ResponsePacket<'_>, DecodeError> {
    let (head, data_section) = validate(buf, check)?;
    let header = ResponseHeader::decode(head)?;
    let len = usize::from(header.data_len);
    if len > data_section.len() {
        return Err(DecodeError::DataLength { declared: header.data_len, capacity: data_section.len() });
    }
    Ok(ResponsePacket { header, data: &data_section[..len], data_section })
}
