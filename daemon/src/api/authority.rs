//! The HTTP/2 `:authority` real gRPC clients send on a Unix socket, made
//! one the server takes.
//!
//! grpc-core (Python grpcio, C++, Ruby) since 1.57 sends the socket path,
//! percent-encoded, as `:authority` (`tmp%2Fecmxfd.sock`); grpc-java and
//! others send the path itself. Neither is an authority RFC 3986 allows,
//! and h2 refuses the stream (RST_STREAM PROTOCOL_ERROR) before any
//! service sees it: every first client failed with "Stream removed" unless
//! told `grpc.default_authority`. A Unix socket has no host to name, so the
//! daemon, which owns its listeners, reads the client's header blocks
//! before h2 does and replaces an authority that does not parse with
//! `localhost`.
//!
//! How, without touching h2: the frames pass through unchanged (the
//! client's own bytes, its HPACK state and all) until a header block whose
//! authority needs the fix. From that block on, every header block of the
//! connection is decoded with the client's HPACK context and written again
//! as literals the server's decoder needs no table for (never indexed,
//! RFC 7541 6.2.3), so the two contexts cannot disagree. Other frames are
//! never touched: their 9-byte headers are read, their bodies go from the
//! socket straight into the server's buffer. The cost: one HPACK decode
//! per header block (a request's handful of headers) on Unix-socket
//! connections, a copy of each frame header, nothing on TCP.

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, ReadBuf};

/// The HTTP/2 client connection preface (RFC 9113 3.4), passed through.
const PREFACE_LEN: usize = 24;
/// Frame types (RFC 9113 6.2, 6.10).
const HEADERS: u8 = 0x1;
const CONTINUATION: u8 = 0x9;
/// Frame flags.
const END_STREAM: u8 = 0x1;
const END_HEADERS: u8 = 0x4;
const PADDED: u8 = 0x8;
const PRIORITY: u8 = 0x20;
/// The largest frame the server accepts (SETTINGS_MAX_FRAME_SIZE default,
/// which it does not raise): the frames written are cut to it.
const MAX_FRAME: usize = 16_384;
/// A header block longer than this is refused (h2 itself caps the decoded
/// list at 16 KiB by default).
const MAX_BLOCK: usize = 64 * 1024;
/// The authority a Unix socket's requests are given.
const LOCAL: &[u8] = b"localhost";

/// A header block being gathered: its HEADERS frame's stream, flags and
/// priority, the fragments so far, and the frames as they came.
struct Block {
    stream: u32,
    end_stream: bool,
    priority: Option<[u8; 5]>,
    fragment: Vec<u8>,
    raw: Vec<u8>,
}

/// A Unix-socket connection whose header blocks get an authority the
/// server takes (module doc). Writes pass through.
pub(crate) struct AuthorityFix<S> {
    io: S,
    /// Read from the client, not yet looked at.
    raw: Vec<u8>,
    /// Ready for the server, from `ready_at` on.
    ready: Vec<u8>,
    ready_at: usize,
    preface_left: usize,
    decoder: fluke_hpack::Decoder<'static>,
    /// Header blocks are written again from here on.
    rewriting: bool,
    block: Option<Block>,
    /// A frame no header block can come from follows: everything passes
    /// through (h2 judges it).
    passing: bool,
    /// Bytes of the current frame that pass through unread (the body of a
    /// frame that is no header block): straight from the socket into the
    /// server's buffer.
    pass_left: usize,
    eof: bool,
}

impl<S> AuthorityFix<S> {
    pub(crate) fn new(io: S) -> Self {
        Self {
            io,
            raw: Vec::new(),
            ready: Vec::new(),
            ready_at: 0,
            preface_left: PREFACE_LEN,
            decoder: fluke_hpack::Decoder::new(),
            rewriting: false,
            block: None,
            passing: false,
            pass_left: 0,
            eof: false,
        }
    }

    /// Moves what can be judged from `raw` to `ready`; false when more
    /// bytes are needed.
    fn step(&mut self) -> io::Result<bool> {
        if self.pass_left > 0 {
            let n = self.pass_left.min(self.raw.len());
            self.pass_left -= n;
            self.ready.extend(self.raw.drain(..n));
            return Ok(n > 0);
        }
        if self.passing || self.preface_left > 0 {
            let n = if self.passing { self.raw.len() } else { self.preface_left.min(self.raw.len()) };
            self.preface_left -= n.min(self.preface_left);
            self.ready.extend(self.raw.drain(..n));
            return Ok(n > 0);
        }
        if self.raw.len() < 9 {
            return Ok(false);
        }
        let len = usize::from(self.raw[0]) << 16 | usize::from(self.raw[1]) << 8 | usize::from(self.raw[2]);
        if len > MAX_FRAME {
            // Not a frame the server takes: it answers it, not us.
            self.passing = true;
            return Ok(true);
        }
        let kind = self.raw[3];
        if self.block.is_none() && kind != HEADERS && kind != CONTINUATION {
            // Not a header block: its header now, its body as it comes.
            self.ready.extend(self.raw.drain(..9));
            self.pass_left = len;
            return Ok(true);
        }
        if self.raw.len() < 9 + len {
            return Ok(false);
        }
        let frame: Vec<u8> = self.raw.drain(..9 + len).collect();
        self.frame(frame)?;
        Ok(true)
    }

    /// One whole frame.
    fn frame(&mut self, frame: Vec<u8>) -> io::Result<()> {
        let (kind, flags) = (frame[3], frame[4]);
        let stream = u32::from_be_bytes([frame[5], frame[6], frame[7], frame[8]]) & 0x7FFF_FFFF;
        let payload = &frame[9..];
        match (kind, self.block.take()) {
            (HEADERS, None) => {
                let Some((priority, fragment)) = headers_fragment(flags, payload) else {
                    self.ready.extend(&frame);
                    return Ok(());
                };
                let block = Block {
                    stream,
                    end_stream: flags & END_STREAM != 0,
                    priority,
                    fragment: fragment.to_vec(),
                    raw: frame.clone(),
                };
                self.gather(block, flags)
            }
            (CONTINUATION, Some(mut block)) if block.stream == stream => {
                block.fragment.extend_from_slice(payload);
                block.raw.extend_from_slice(&frame);
                self.gather(block, flags)
            }
            (_, block) => {
                // Anything else (a frame inside a header block is the
                // client's protocol error, h2's to answer) as it came.
                if let Some(b) = block {
                    self.ready.extend(&b.raw);
                }
                self.ready.extend(&frame);
                Ok(())
            }
        }
    }

    fn gather(&mut self, block: Block, flags: u8) -> io::Result<()> {
        if block.fragment.len() > MAX_BLOCK {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "HTTP/2 header block over 64 KiB"));
        }
        if flags & END_HEADERS == 0 {
            self.block = Some(block);
            return Ok(());
        }
        let headers = match self.decoder.decode(&block.fragment) {
            Ok(h) => h,
            Err(_) => {
                // The server's decoder fails on it too, and says so.
                self.ready.extend(&block.raw);
                return Ok(());
            }
        };
        if !self.rewriting && !headers.iter().any(|(n, v)| needs_local(n, v)) {
            self.ready.extend(&block.raw);
            return Ok(());
        }
        self.rewriting = true;
        let mut encoded = Vec::new();
        for (name, value) in &headers {
            let value: &[u8] = if needs_local(name, value) { LOCAL } else { value };
            never_indexed(name, value, &mut encoded);
        }
        write_headers(&block, &encoded, &mut self.ready);
        Ok(())
    }
}

/// Whether a header is an `:authority` h2 would refuse (a socket path).
fn needs_local(name: &[u8], value: &[u8]) -> bool {
    name == b":authority" && http::uri::Authority::try_from(value).is_err()
}

/// A HEADERS payload's priority fields and header block fragment (padding
/// and its length taken off); `None` when the lengths do not add up.
fn headers_fragment(flags: u8, payload: &[u8]) -> Option<(Option<[u8; 5]>, &[u8])> {
    let (pad, mut rest) =
        if flags & PADDED != 0 { (usize::from(*payload.first()?), &payload[1..]) } else { (0, payload) };
    let priority = if flags & PRIORITY != 0 {
        let p: [u8; 5] = rest.get(..5)?.try_into().ok()?;
        rest = &rest[5..];
        Some(p)
    } else {
        None
    };
    let end = rest.len().checked_sub(pad)?;
    Some((priority, &rest[..end]))
}

/// An HPACK integer with an `n`-bit prefix (RFC 7541 5.1).
fn integer(value: usize, n: u8, first: u8, out: &mut Vec<u8>) {
    let max = (1usize << n) - 1;
    if value < max {
        out.push(first | value as u8);
        return;
    }
    out.push(first | max as u8);
    let mut rest = value - max;
    while rest >= 128 {
        out.push((rest % 128) as u8 | 0x80);
        rest /= 128;
    }
    out.push(rest as u8);
}

/// A literal header field never indexed, with a literal name (RFC 7541
/// 6.2.3), strings without Huffman coding.
fn never_indexed(name: &[u8], value: &[u8], out: &mut Vec<u8>) {
    out.push(0x10);
    for s in [name, value] {
        integer(s.len(), 7, 0, out);
        out.extend_from_slice(s);
    }
}

/// The block as HEADERS and CONTINUATION frames of at most [`MAX_FRAME`].
fn write_headers(block: &Block, encoded: &[u8], out: &mut Vec<u8>) {
    let priority = block.priority.map(|p| p.to_vec()).unwrap_or_default();
    let first_room = MAX_FRAME - priority.len();
    let (first, mut rest) = encoded.split_at(encoded.len().min(first_room));
    let mut flags = if block.end_stream { END_STREAM } else { 0 };
    if block.priority.is_some() {
        flags |= PRIORITY;
    }
    if rest.is_empty() {
        flags |= END_HEADERS;
    }
    frame_header(priority.len() + first.len(), HEADERS, flags, block.stream, out);
    out.extend_from_slice(&priority);
    out.extend_from_slice(first);
    while !rest.is_empty() {
        let (chunk, after) = rest.split_at(rest.len().min(MAX_FRAME));
        rest = after;
        let flags = if rest.is_empty() { END_HEADERS } else { 0 };
        frame_header(chunk.len(), CONTINUATION, flags, block.stream, out);
        out.extend_from_slice(chunk);
    }
}

fn frame_header(len: usize, kind: u8, flags: u8, stream: u32, out: &mut Vec<u8>) {
    out.extend_from_slice(&(len as u32).to_be_bytes()[1..]);
    out.push(kind);
    out.push(flags);
    out.extend_from_slice(&stream.to_be_bytes());
}

impl<S: AsyncRead + Unpin> AsyncRead for AuthorityFix<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        loop {
            if this.ready_at < this.ready.len() {
                let n = buf.remaining().min(this.ready.len() - this.ready_at);
                buf.put_slice(&this.ready[this.ready_at..this.ready_at + n]);
                this.ready_at += n;
                if this.ready_at == this.ready.len() {
                    this.ready.clear();
                    this.ready_at = 0;
                }
                return Poll::Ready(Ok(()));
            }
            if this.step()? {
                continue;
            }
            if this.eof {
                // What is left is no whole frame: as it came, then the end.
                if !this.raw.is_empty() {
                    this.ready.append(&mut this.raw);
                    continue;
                }
                return Poll::Ready(Ok(()));
            }
            if this.pass_left > 0 && this.raw.is_empty() {
                // A body passing through: read it where the server wants it.
                let limit = this.pass_left.min(buf.remaining());
                let mut direct = ReadBuf::new(buf.initialize_unfilled_to(limit));
                return match Pin::new(&mut this.io).poll_read(cx, &mut direct) {
                    Poll::Ready(Ok(())) => {
                        let n = direct.filled().len();
                        buf.advance(n);
                        this.pass_left -= n;
                        Poll::Ready(Ok(()))
                    }
                    other => other,
                };
            }
            let mut chunk = [0u8; 4096];
            let mut read = ReadBuf::new(&mut chunk);
            match Pin::new(&mut this.io).poll_read(cx, &mut read) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Ready(Ok(())) if read.filled().is_empty() => this.eof = true,
                Poll::Ready(Ok(())) => this.raw.extend_from_slice(read.filled()),
            }
        }
    }
}

crate::admission::writes_and_peer_from_io!(AuthorityFix);

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(kind: u8, flags: u8, stream: u32, payload: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        frame_header(payload.len(), kind, flags, stream, &mut out);
        out.extend_from_slice(payload);
        out
    }

    /// Feeds `input` through and returns what the server would read.
    fn through(input: &[u8]) -> Vec<u8> {
        let mut fix = AuthorityFix::new(());
        fix.raw.extend_from_slice(input);
        while fix.step().unwrap() {}
        fix.ready
    }

    fn decode(frames: &[u8]) -> Vec<Vec<(Vec<u8>, Vec<u8>)>> {
        let mut d = fluke_hpack::Decoder::new();
        let mut out = Vec::new();
        let mut at = PREFACE_LEN;
        while at + 9 <= frames.len() {
            let len = usize::from(frames[at]) << 16 | usize::from(frames[at + 1]) << 8 | usize::from(frames[at + 2]);
            if frames[at + 3] == HEADERS {
                let (_, frag) = headers_fragment(frames[at + 4], &frames[at + 9..at + 9 + len]).unwrap();
                out.push(d.decode(frag).unwrap());
            }
            at += 9 + len;
        }
        out
    }

    fn request(authority: &[u8]) -> Vec<(&'static [u8], Vec<u8>)> {
        vec![
            (b":method", b"POST".to_vec()),
            (b":scheme", b"http".to_vec()),
            (b":path", b"/grpc.health.v1.Health/Check".to_vec()),
            (b":authority", authority.to_vec()),
            (b"te", b"trailers".to_vec()),
        ]
    }

    /// A client's two requests, its encoder indexing as grpc-core's does.
    fn client(authorities: [&[u8]; 2]) -> Vec<u8> {
        let mut enc = fluke_hpack::Encoder::new();
        let mut out = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n".to_vec();
        out.extend(frame(0x4, 0, 0, &[]));
        for (k, a) in authorities.into_iter().enumerate() {
            let headers = request(a);
            let block = enc.encode(headers.iter().map(|(n, v)| (*n, &v[..])));
            out.extend(frame(HEADERS, END_HEADERS, 1 + 2 * k as u32, &block));
            out.extend(frame(0x0, END_STREAM, 1 + 2 * k as u32, &[0, 0, 0, 0, 0]));
        }
        out
    }

    #[test]
    fn a_good_authority_passes_byte_for_byte() {
        let input = client([b"localhost", b"localhost"]);
        assert_eq!(through(&input), input);
    }

    #[test]
    fn a_socket_path_becomes_localhost_in_every_later_block() {
        let input = client([b"tmp%2Fecmxfd.sock", b"tmp%2Fecmxfd.sock"]);
        let out = through(&input);
        let blocks = decode(&out);
        assert_eq!(blocks.len(), 2);
        for b in &blocks {
            let authority = b.iter().find(|(n, _)| n == b":authority").map(|(_, v)| v.clone());
            assert_eq!(authority.as_deref(), Some(LOCAL));
            assert!(b.iter().any(|(n, v)| n == b":path" && v == b"/grpc.health.v1.Health/Check"));
        }
        // Data frames are the client's own.
        assert!(out.windows(14).any(|w| w == &frame(0x0, END_STREAM, 3, &[0, 0, 0, 0, 0])[..]));
    }

    #[test]
    fn padding_priority_and_continuation_are_read_and_written_back() {
        let mut enc = fluke_hpack::Encoder::new();
        let headers = request(b"/run/ecmxfd/ecmxfd.sock");
        let block = enc.encode(headers.iter().map(|(n, v)| (*n, &v[..])));
        let (a, b) = block.split_at(block.len() / 2);
        let mut payload = vec![3];
        payload.extend([0x80, 0, 0, 0, 15]);
        payload.extend(a);
        payload.extend([0, 0, 0]);
        let mut input = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n".to_vec();
        input.extend(frame(HEADERS, PADDED | PRIORITY | END_STREAM, 1, &payload));
        input.extend(frame(CONTINUATION, END_HEADERS, 1, b));
        let out = through(&input);
        assert_eq!(out[PREFACE_LEN + 4], PRIORITY | END_STREAM | END_HEADERS);
        assert_eq!(&out[PREFACE_LEN + 9..PREFACE_LEN + 14], &[0x80, 0, 0, 0, 15]);
        let got = &decode(&out)[0];
        assert!(got.iter().any(|(n, v)| n == b":authority" && v == LOCAL), "{got:?}");
    }

    #[test]
    fn a_long_block_is_cut_into_continuations() {
        let mut out = Vec::new();
        let block = Block { stream: 5, end_stream: false, priority: None, fragment: Vec::new(), raw: Vec::new() };
        write_headers(&block, &vec![7u8; MAX_FRAME + 10], &mut out);
        assert_eq!((out[3], out[4]), (HEADERS, 0));
        assert_eq!(&out[..3], &[0x00, 0x40, 0x00]);
        let second = 9 + MAX_FRAME;
        assert_eq!((out[second + 3], out[second + 4]), (CONTINUATION, END_HEADERS));
        let mut n = Vec::new();
        integer(1337, 5, 0, &mut n);
        assert_eq!(n, vec![31, 154, 10], "RFC 7541 C.1.2");
    }
}
