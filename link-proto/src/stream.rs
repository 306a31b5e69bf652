//! [`Links`] over `embedded-io` byte streams (UART, SPI-as-stream), framed
//! with [`crate::framing`].
//!
//! Each port ([`StreamPort`]) owns its stream, a one-frame transmit queue of
//! encoded bytes and a [`StreamDecoder`]. Nothing blocks: bytes are read only
//! while [`ReadReady::read_ready`] says so and written only while
//! [`WriteReady::write_ready`] says so. A queued frame drains whenever its
//! port is used, or on [`Links::poll`].
//!
//! Memory: a face port holds about `2 * FRAME_WIRE_LEN_MAX` bytes, the global
//! port about `2 * PACKET_WIRE_LEN_MAX`; place [`StreamLinks`] in a static on
//! the board.
//!
//! # Panics
//!
//! Nothing here panics, whatever the streams deliver.

use embedded_io::{Error as _, ErrorKind, Read, ReadReady, Write, WriteReady};

use crate::framing::{encode_wire, StreamDecoder};
use crate::limits::{
    FRAME_COBS_LEN_MAX, FRAME_WIRE_LEN_MAX, PACKET_COBS_LEN_MAX, PACKET_WIRE_LEN_MAX,
};
use crate::link::{Face, Links, RecvError, SendError};

/// Bytes read from the stream per `read` call.
pub const READ_CHUNK: usize = 64;

/// One framed link over a byte stream. `RX` is the decoder's encoded-frame
/// capacity, `TX` the transmit queue (one encoded frame with delimiters).
#[derive(Debug)]
pub struct StreamPort<S, const RX: usize, const TX: usize> {
    stream: S,
    rx: StreamDecoder<RX>,
    chunk: [u8; READ_CHUNK],
    chunk_pos: usize,
    chunk_len: usize,
    tx: [u8; TX],
    tx_pos: usize,
    tx_len: usize,
}

/// A face port sized for the largest link frame.
pub type FacePort<S> = StreamPort<S, FRAME_COBS_LEN_MAX, FRAME_WIRE_LEN_MAX>;
/// A global port sized for the largest packet.
pub type GlobalPort<S> = StreamPort<S, PACKET_COBS_LEN_MAX, PACKET_WIRE_LEN_MAX>;

impl<S, const RX: usize, const TX: usize> StreamPort<S, RX, TX>
where
    S: Read + Write + ReadReady + WriteReady,
{
    /// A port over `stream`, queues empty (a `const fn`, so a port can be a static built at
    /// compile time rather than on a small stack).
    pub const fn new(stream: S) -> Self {
        StreamPort {
            stream,
            rx: StreamDecoder::new(),
            chunk: [0; READ_CHUNK],
            chunk_pos: 0,
            chunk_len: 0,
            tx: [0; TX],
            tx_pos: 0,
            tx_len: 0,
        }
    }

    /// The stream.
    pub fn stream(&self) -> &S {
        &self.stream
    }

    /// Puts `stream` under the port (queues emptied), returning the old one.
    pub fn replace_stream(&mut self, stream: S) -> S {
        self.rx = StreamDecoder::new();
        (self.chunk_pos, self.chunk_len, self.tx_pos, self.tx_len) = (0, 0, 0, 0);
        core::mem::replace(&mut self.stream, stream)
    }

    /// The stream, mutable.
    pub fn stream_mut(&mut self) -> &mut S {
        &mut self.stream
    }

    /// Gives the stream back.
    pub fn into_inner(self) -> S {
        self.stream
    }

    /// Whether a frame is still (partly) waiting in the transmit queue.
    pub fn tx_pending(&self) -> bool {
        self.tx_pos < self.tx_len
    }

    /// Writes queued bytes while the stream accepts them.
    pub fn poll_tx(&mut self) -> Result<(), ErrorKind> {
        while self.tx_pos < self.tx_len {
            if !self.stream.write_ready().map_err(|e| e.kind())? {
                break;
            }
            let pending = self.tx.get(self.tx_pos..self.tx_len).unwrap_or(&[]);
            let n = self.stream.write(pending).map_err(|e| e.kind())?;
            if n == 0 {
                return Err(ErrorKind::WriteZero);
            }
            self.tx_pos = (self.tx_pos + n).min(self.tx_len);
        }
        Ok(())
    }

    /// Queues one frame. `Err(WouldBlock)` while the previous one is still draining.
    pub fn try_send(&mut self, frame: &[u8]) -> Result<(), SendError> {
        self.poll_tx().map_err(SendError::Io)?;
        if self.tx_pending() {
            return Err(SendError::WouldBlock);
        }
        let n = encode_wire(frame, &mut self.tx).map_err(|_| SendError::TooLong)?;
        self.tx_pos = 0;
        self.tx_len = n;
        self.poll_tx().map_err(SendError::Io)
    }

    /// Receives one whole frame into `buf`, reading at most about two frames'
    /// worth of bytes per call so a babbling stream cannot hold the caller.
    pub fn try_recv(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.poll_tx().map_err(RecvError::Io)?;
        let mut budget = 2 * TX;
        loop {
            while self.chunk_pos < self.chunk_len {
                let byte = self.chunk.get(self.chunk_pos).copied().unwrap_or(0);
                self.chunk_pos += 1;
                match self.rx.feed(byte) {
                    None => {}
                    Some(Err(e)) => return Err(RecvError::Damaged(e)),
                    Some(Ok(frame)) => {
                        let out = buf
                            .get_mut(..frame.len())
                            .ok_or(RecvError::BufferTooSmall {
                                needed: frame.len(),
                            })?;
                        out.copy_from_slice(frame);
                        return Ok(Some(frame.len()));
                    }
                }
            }
            if budget == 0
                || !self
                    .stream
                    .read_ready()
                    .map_err(|e| RecvError::Io(e.kind()))?
            {
                return Ok(None);
            }
            let n = self
                .stream
                .read(&mut self.chunk)
                .map_err(|e| RecvError::Io(e.kind()))?;
            if n == 0 {
                return Ok(None); // end of stream
            }
            self.chunk_pos = 0;
            self.chunk_len = n.min(READ_CHUNK);
            budget = budget.saturating_sub(n);
        }
    }
}

/// [`Links`] over six optional face streams (`None` at the array's edge) and
/// one global stream. All faces share the stream type `F` (wrap different
/// peripherals in an enum if needed).
#[derive(Debug)]
pub struct StreamLinks<F, G> {
    faces: [Option<FacePort<F>>; Face::COUNT],
    global: GlobalPort<G>,
}

impl<F, G> StreamLinks<F, G>
where
    F: Read + Write + ReadReady + WriteReady,
    G: Read + Write + ReadReady + WriteReady,
{
    /// Only the global port, over `global` (a `const fn`: the links, over 170 KB of
    /// buffers, can be a static built at compile time, never a stack temporary).
    pub const fn unlinked(global: G) -> Self {
        StreamLinks {
            faces: [const { None }; Face::COUNT],
            global: StreamPort::new(global),
        }
    }

    /// Links over ports the caller built (a `const fn`, so a board's static can hold a port
    /// for every face, made at compile time, and link or unlink each at start with
    /// [`StreamLinks::relink`] once it knows its place in the machine).
    pub const fn from_ports(
        faces: [Option<FacePort<F>>; Face::COUNT],
        global: GlobalPort<G>,
    ) -> Self {
        StreamLinks { faces, global }
    }

    /// Puts `stream` under `face` (its port's queues emptied), or with `None` takes the face
    /// off: sends and receives on it then say `NoLink`. A face that already has a port keeps
    /// its buffers (nothing large is built); one without gets a new port.
    pub fn relink(&mut self, face: Face, stream: Option<F>) {
        let Some(slot) = self.faces.get_mut(face.index()) else {
            return;
        };
        match (slot.as_mut(), stream) {
            (Some(port), Some(s)) => {
                port.replace_stream(s);
            }
            (None, Some(s)) => *slot = Some(StreamPort::new(s)),
            (_, None) => *slot = None,
        }
    }

    /// Links over the given streams, indexed by [`Face::index`].
    pub fn new(faces: [Option<F>; Face::COUNT], global: G) -> Self {
        StreamLinks {
            faces: faces.map(|s| s.map(StreamPort::new)),
            global: StreamPort::new(global),
        }
    }

    /// The port of a face, if linked.
    pub fn face_port(&mut self, face: Face) -> Option<&mut FacePort<F>> {
        self.faces.get_mut(face.index())?.as_mut()
    }

    /// The global port.
    pub fn global_port(&mut self) -> &mut GlobalPort<G> {
        &mut self.global
    }
}

impl<F, G> Links for StreamLinks<F, G>
where
    F: Read + Write + ReadReady + WriteReady,
    G: Read + Write + ReadReady + WriteReady,
{
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        self.face_port(face)
            .ok_or(SendError::NoLink)?
            .try_send(frame)
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.face_port(face).ok_or(RecvError::NoLink)?.try_recv(buf)
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        self.global.try_send(packet)
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.global.try_recv(buf)
    }

    /// Drains every transmit queue as far as the streams accept; stream
    /// errors surface on the next send or receive of that port.
    fn poll(&mut self) {
        for port in self.faces.iter_mut().flatten() {
            let _ = port.poll_tx();
        }
        let _ = self.global.poll_tx();
    }
}
