//! CoE server: SDO download/upload (expedited, normal, segmented, complete access), SDO
//! information and the abort-code rules.

use oxicat_wire::coe::{
    od_list_type, CoeHeader, CoeService, SdoAbortCode, SdoInfoOpcode, SdoInfoRef, SdoRef,
    SdoRequestCommand, COE_HEADER_LEN, SDO_INFO_HEADER_LEN,
};
use oxicat_wire::mailbox::{MailboxErrorDetail, MailboxType};

use crate::device::{PdoEntry, SyncMode};
use crate::esm::AlState;
use crate::od::{DataType, EntryDef, Kind, Obj, ObjectCode, MAX_ASSIGN, MAX_PDO_ENTRIES};
use crate::pdi::Pdi;
use crate::pdo::{self, Dir, MAX_PD_BYTES};
use crate::slave::{Application, Slave};

/// State of a multi-message SDO service.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) enum SdoState {
    /// Nothing in progress.
    #[default]
    Idle,
    /// Segmented download in progress.
    Download {
        index: u16,
        sub: u8,
        ca: bool,
        size: usize,
        got: usize,
        toggle: bool,
        /// Written straight into the image (too large to stage).
        direct: bool,
    },
    /// Segmented upload in progress.
    Upload {
        index: u16,
        sub: u8,
        ca: bool,
        size: usize,
        sent: usize,
        toggle: bool,
    },
    /// A fragmented OD list reply in progress.
    InfoList {
        list_type: u16,
        next: usize,
        left: u16,
    },
}

type Abort = SdoAbortCode;

fn get_bit(b: &[u8], i: usize) -> bool {
    b.get(i / 8).is_some_and(|x| (x >> (i % 8)) & 1 != 0)
}

fn set_bit(b: &mut [u8], i: usize, v: bool) {
    if let Some(x) = b.get_mut(i / 8) {
        if v {
            *x |= 1 << (i % 8);
        } else {
            *x &= !(1 << (i % 8));
        }
    }
}

/// Walks the complete-access stream layout of `o` from subindex `start` (subindex 0 as 8
/// bits in a 16-bit slot, a whole-byte entry from the next byte boundary) and copies each
/// entry's bits: `to_stream`, from the object's image bytes `src` into `dst`, the window of
/// the stream that starts at stream byte `w0`; else from the stream `src` into the object's
/// image bytes `dst`. An empty `dst` copies nothing. Returns the stream bits and whether
/// subindex 0 and any other subindex are in the stream. One function for the layout and both
/// copies (a closure per use made a copy of the walk for each of its three callers).
fn ca_copy(
    o: &Obj,
    start: u8,
    src: &[u8],
    dst: &mut [u8],
    to_stream: bool,
    w0: usize,
) -> (usize, bool, bool) {
    let (mut pos, mut off) = (0usize, 0usize);
    let (mut sub0, mut high) = (false, false);
    for (sub, e) in o.entries.iter() {
        if sub >= start {
            let bits = if sub == 0 {
                sub0 = true;
                8
            } else {
                high = true;
                if e.bits % 8 == 0 {
                    pos = pos.div_ceil(8) * 8;
                }
                e.bits as usize
            };
            if !dst.is_empty() {
                for k in 0..bits {
                    // Stream bit `pos + k`, image bit `off * 8 + k`; a stream bit before
                    // the window wraps to an index `set_bit` ignores.
                    let (from, to) = if to_stream {
                        (off * 8 + k, (pos + k).wrapping_sub(w0 * 8))
                    } else {
                        (pos + k, off * 8 + k)
                    };
                    set_bit(dst, to, get_bit(src, from));
                }
            }
            pos += if sub == 0 { 16 } else { bits };
        }
        off += e.storage_len();
    }
    (pos, sub0, high)
}

/// Writes the CoE header of a reply of `service` (number 0) and the byte after it (the SDO
/// command or the SDO information opcode): `CoeHeader::write` without its checks of
/// fields the stack never sets out of range, in each reply path.
fn coe_head(b: &mut [u8], service: CoeService, cmd: u8) {
    b[0] = 0;
    b[1] = service.code() << 4;
    b[2] = cmd;
}

fn size_abort(size: usize, needed: usize) -> Option<Abort> {
    if size > needed {
        Some(Abort::LengthTooHigh)
    } else if size < needed {
        Some(Abort::LengthTooLow)
    } else {
        None
    }
}

/// Minimum and maximum of an entry as raw little-endian bits: the definition's range for
/// integers when it has one, else the limits of the data type; `None` for strings.
fn value_limits(e: &EntryDef) -> Option<(u64, u64)> {
    let bits = e.bits.clamp(1, 64) as u32;
    Some(match e.dtype {
        DataType::Bool => (0, 1),
        DataType::Real32 => (f32::MIN.to_bits() as u64, f32::MAX.to_bits() as u64),
        DataType::Real64 => (f64::MIN.to_bits(), f64::MAX.to_bits()),
        DataType::VisibleString | DataType::OctetString => return None,
        _ if e.limits.has_range() => (e.limits.range.0 as u64, e.limits.range.1 as u64),
        t if t.is_signed() => {
            let max = (u64::MAX >> (65 - bits)) as i64;
            ((-max - 1) as u64, max as u64)
        }
        _ => (0, u64::MAX >> (64 - bits)),
    })
}

/// The 32-bit value of an abort code: one copy of the code table in a board image for the
/// SDO aborts and the SDO information errors (inlined, each caller had its own).
#[cfg_attr(target_os = "none", inline(never))]
fn abort_code(c: Abort) -> u32 {
    c.code()
}

/// Value of an integer entry as i128 from its image bytes.
fn int_value(e: &EntryDef, b: &[u8]) -> i128 {
    let mut a = [0u8; 8];
    let n = b.len().min(8);
    a[..n].copy_from_slice(&b[..n]);
    let u = u64::from_le_bytes(a);
    let bits = e.bits.min(64) as u32;
    if e.dtype.is_signed() && bits < 64 {
        let sh = 64 - bits;
        (((u << sh) as i64) >> sh) as i128
    } else if e.dtype.is_signed() {
        u as i64 as i128
    } else {
        u as i128
    }
}

impl<P: Pdi, const N: usize, const M: usize, const K: usize> Slave<P, N, M, K> {
    // Not inlined: inlined into the firmware's main loop, its buffers joined `main`'s frame
    // and its code was copied per caller (minimal image: 1.4 KB flash, 232 B stack).
    #[inline(never)]
    pub(crate) fn coe_request<A: Application<N>>(&mut self, app: &mut A, p: &[u8]) {
        let Ok(h) = CoeHeader::parse(p) else {
            self.mbx_error(MailboxErrorDetail::SizeTooShort);
            return;
        };
        match h.service {
            CoeService::SdoRequest => self.sdo_request(app, p),
            CoeService::SdoInformation => self.info_request(p),
            _ => self.mbx_error(MailboxErrorDetail::ServiceNotSupported),
        }
    }

    fn abort(&mut self, index: u16, sub: u8, code: Abort) {
        self.sdo = SdoState::Idle;
        // An abort is an SDO request frame with command 0x80 and the code as its data.
        let code = abort_code(code).to_le_bytes();
        self.sdo_frame(CoeService::SdoRequest, 0x80, index, sub, code);
    }

    /// Queues a 10-byte SDO frame of `service`: command, index, subindex and the 4 data
    /// bytes of the header (an abort, the download responses).
    fn sdo_frame(&mut self, service: CoeService, cmd: u8, index: u16, sub: u8, hdata: [u8; 4]) {
        let mut b = [0u8; 10];
        coe_head(&mut b, service, cmd);
        b[3..5].copy_from_slice(&index.to_le_bytes());
        b[5] = sub;
        b[6..10].copy_from_slice(&hdata);
        self.queue_reply(MailboxType::Coe, &b);
    }

    fn sdo_request<A: Application<N>>(&mut self, app: &mut A, p: &[u8]) {
        if p.len() < 10 {
            self.mbx_error(MailboxErrorDetail::SizeTooShort);
            return;
        }
        let Ok(s) = SdoRef::parse(p) else {
            self.mbx_error(MailboxErrorDetail::InvalidHeader);
            return;
        };
        let (index, sub) = s.index().unwrap_or((0, 0));
        let cmd = match SdoRequestCommand::from_u8(s.command) {
            Ok(c) => c,
            Err(_) => return self.abort(index, sub, Abort::InvalidCommand),
        };
        match cmd {
            SdoRequestCommand::Abort => self.sdo = SdoState::Idle,
            SdoRequestCommand::InitiateDownload {
                size_indicated,
                expedited,
                unused,
                complete_access,
            } => {
                self.sdo = SdoState::Idle;
                let r = self.initiate_download(
                    app,
                    &s,
                    index,
                    sub,
                    complete_access,
                    expedited,
                    size_indicated,
                    unused,
                );
                match r {
                    Ok(()) => self.sdo_frame(CoeService::SdoResponse, 0x60, index, sub, [0; 4]),
                    Err(c) => self.abort(index, sub, c),
                }
            }
            SdoRequestCommand::DownloadSegment { toggle, last, .. } => {
                self.download_segment(app, &s, toggle, last)
            }
            SdoRequestCommand::InitiateUpload { complete_access } => {
                self.sdo = SdoState::Idle;
                if let Err(c) = self.initiate_upload(index, sub, complete_access) {
                    self.abort(index, sub, c);
                }
            }
            SdoRequestCommand::UploadSegment { toggle } => self.upload_segment(toggle),
        }
    }

    /// Resolves and access-checks a transfer target; returns the object and the stream size.
    fn target(&self, index: u16, sub: u8, ca: bool, write: bool) -> Result<(Obj, usize), Abort> {
        let o = self.od.find(index).ok_or(Abort::ObjectDoesNotExist)?;
        let st = self.state;
        let check = |e: &EntryDef| -> Result<(), Abort> {
            let access = o.access(e);
            if write {
                if !access.writable() {
                    return Err(Abort::ReadOnly);
                }
                if !access.write_in(st) {
                    return Err(Abort::CannotTransferDeviceState);
                }
            } else {
                if !access.readable() {
                    return Err(Abort::WriteOnly);
                }
                if !access.read_in(st) {
                    return Err(Abort::CannotTransferDeviceState);
                }
            }
            Ok(())
        };
        if !ca {
            let (_, e, off) = o.entry(sub).ok_or(Abort::SubindexDoesNotExist)?;
            check(e)?;
            let size = if e.dtype == DataType::VisibleString && !write {
                let b = self.od.bytes_of(&o, off, e.storage_len());
                b.iter().position(|&c| c == 0).unwrap_or(b.len())
            } else {
                e.storage_len()
            };
            return Ok((o, size));
        }
        if sub > 1 {
            return Err(Abort::UnsupportedAccess);
        }
        if o.entry(sub).is_none() {
            return Err(Abort::SubindexDoesNotExist);
        }
        if o.code == ObjectCode::Var || o.entries.defs().iter().any(|e| e.dtype.is_string()) {
            return Err(Abort::CompleteAccessUnsupported);
        }
        for (_, e) in o.entries.iter().filter(|&(s, _)| s >= sub) {
            check(e)?;
        }
        let (bits, _, _) = ca_copy(&o, sub, &[], &mut [], false, 0);
        Ok((o, bits.div_ceil(8)))
    }

    /// Reads `out.len()` bytes of the transfer stream from byte `off`.
    fn stream_read(&self, o: &Obj, sub: u8, ca: bool, off: usize, out: &mut [u8]) {
        out.fill(0);
        if !ca {
            if let Some((_, e, ioff)) = o.entry(sub) {
                let b = self.od.bytes_of(o, ioff, e.storage_len());
                let n = out.len().min(b.len().saturating_sub(off));
                out[..n].copy_from_slice(&b[off..off + n]);
            }
            return;
        }
        let obj_len: usize = o.entries.iter().map(|(_, e)| e.storage_len()).sum();
        let img = self.od.bytes_of(o, o.base, obj_len);
        ca_copy(o, sub, img, out, true, off);
    }

    #[allow(clippy::too_many_arguments)]
    fn initiate_download<A: Application<N>>(
        &mut self,
        app: &mut A,
        s: &SdoRef<'_>,
        index: u16,
        sub: u8,
        ca: bool,
        expedited: bool,
        size_indicated: bool,
        unused: u8,
    ) -> Result<(), Abort> {
        let (o, needed) = self.target(index, sub, ca, true)?;
        if !ca && self.state >= AlState::SafeOp {
            if let Some((_, e, off)) = o.entry(sub) {
                if self
                    .rx_mapping()
                    .maps(o.area == crate::od::Area::App, off, e.storage_len())
                {
                    return Err(Abort::MappedToRxPdo);
                }
            }
        }
        let (size, data): (usize, &[u8]) = if expedited {
            let n = if size_indicated {
                4 - unused as usize
            } else {
                needed.min(4)
            };
            (n, s.rest.get(3..3 + n).ok_or(Abort::LengthTooLow)?)
        } else {
            let (sz, d) = s.normal_data().map_err(|_| Abort::LengthTooLow)?;
            let sz = sz as usize;
            if !size_indicated && sz == 0 {
                return Err(Abort::LengthMismatch);
            }
            (sz, &d[..d.len().min(sz)])
        };
        let e = if ca { None } else { o.entry(sub).map(|x| x.1) };
        match e {
            Some(e) if e.dtype == DataType::VisibleString => {
                if size > needed {
                    return Err(Abort::LengthTooHigh);
                }
            }
            _ => {
                if let Some(c) = size_abort(size, needed) {
                    return Err(c);
                }
            }
        }
        if data.len() >= size {
            if size > M {
                return Err(Abort::ObjectTooLong);
            }
            // The request is the caller's copy, not the stack's buffer: no second copy.
            return self.commit(app, &o, sub, ca, &data[..size]);
        }
        // Segmented download follows.
        let direct = size > M;
        if direct {
            if ca || !e.is_some_and(|e| e.dtype.is_string()) {
                return Err(Abort::ObjectTooLong);
            }
            if let Some((_, e, off)) = o.entry(sub) {
                let img = self.od.bytes_of_mut(&o, off, e.storage_len());
                img.fill(0);
                img[..data.len()].copy_from_slice(data);
            }
        } else {
            self.mbx.stage[..data.len()].copy_from_slice(data);
        }
        self.sdo = SdoState::Download {
            index,
            sub,
            ca,
            size,
            got: data.len(),
            toggle: false,
            direct,
        };
        Ok(())
    }

    fn download_segment<A: Application<N>>(
        &mut self,
        app: &mut A,
        s: &SdoRef<'_>,
        toggle: bool,
        last: bool,
    ) {
        let SdoState::Download {
            index,
            sub,
            ca,
            size,
            got,
            toggle: t,
            direct,
        } = self.sdo
        else {
            return self.abort(0, 0, Abort::InvalidCommand);
        };
        if toggle != t {
            return self.abort(index, sub, Abort::ToggleBit);
        }
        let data = s.segment_data().unwrap_or(&[]);
        if got + data.len() > size {
            return self.abort(index, sub, Abort::LengthTooHigh);
        }
        let Some(o) = self.od.find(index) else {
            return self.abort(index, sub, Abort::ObjectDoesNotExist);
        };
        if direct {
            if let Some((_, e, off)) = o.entry(sub) {
                let img = self.od.bytes_of_mut(&o, off, e.storage_len());
                img[got..got + data.len()].copy_from_slice(data);
            }
        } else {
            self.mbx.stage[got..got + data.len()].copy_from_slice(data);
        }
        let got = got + data.len();
        if last {
            self.sdo = SdoState::Idle;
            if got != size {
                return self.abort(index, sub, Abort::LengthTooLow);
            }
            if !direct {
                let mut tmp = [0u8; M];
                tmp[..size].copy_from_slice(&self.mbx.stage[..size]);
                if let Err(c) = self.commit(app, &o, sub, ca, &tmp[..size]) {
                    return self.abort(index, sub, c);
                }
            } else {
                app.sdo_written(index, sub, &mut self.od);
            }
        } else {
            self.sdo = SdoState::Download {
                index,
                sub,
                ca,
                size,
                got,
                toggle: !t,
                direct,
            };
        }
        let cmd = 0x20 | if toggle { 0x10 } else { 0 };
        let mut b = [0u8; 10];
        coe_head(&mut b, CoeService::SdoResponse, cmd);
        self.queue_reply(MailboxType::Coe, &b);
    }

    /// Validates and stores a complete download.
    fn commit<A: Application<N>>(
        &mut self,
        app: &mut A,
        o: &Obj,
        sub: u8,
        ca: bool,
        data: &[u8],
    ) -> Result<(), Abort> {
        let obj_len: usize = o.entries.iter().map(|(_, e)| e.storage_len()).sum();
        if obj_len > M {
            return Err(Abort::ObjectTooLong);
        }
        // Work on a copy of the object's values, validate, then store.
        let mut tmp = [0u8; M];
        tmp[..obj_len].copy_from_slice(self.od.bytes_of(o, o.base, obj_len));
        let written_sub0;
        let written_high;
        if ca {
            (_, written_sub0, written_high) = ca_copy(o, sub, data, &mut tmp[..obj_len], false, 0);
        } else {
            let (_, e, off) = o.entry(sub).ok_or(Abort::SubindexDoesNotExist)?;
            let r = off - o.base;
            let l = e.storage_len();
            tmp[r..r + l].fill(0);
            tmp[r..r + data.len().min(l)].copy_from_slice(&data[..data.len().min(l)]);
            written_sub0 = sub == 0;
            written_high = sub != 0;
        }
        // Plain value checks on every written entry.
        let mut eoff = 0;
        for (s, e) in o.entries.iter() {
            let l = e.storage_len();
            let in_scope = if ca { s >= sub } else { s == sub };
            if in_scope {
                let v = &tmp[eoff..eoff + l];
                if e.dtype == DataType::Bool && v[0] > 1 {
                    return Err(Abort::ValueRangeExceeded);
                }
                let (min, max) = e.limits.range;
                if e.dtype.is_integer() && min <= max {
                    let x = int_value(e, v);
                    if x > max as i128 {
                        return Err(Abort::ValueTooHigh);
                    }
                    if x < min as i128 {
                        return Err(Abort::ValueTooLow);
                    }
                }
            }
            eoff += l;
        }
        self.check_kind(o, &tmp[..obj_len], written_sub0, written_high, ca)?;
        self.od
            .bytes_of_mut(o, o.base, obj_len)
            .copy_from_slice(&tmp[..obj_len]);
        app.sdo_written(o.index, sub, &mut self.od);
        Ok(())
    }

    /// The subindex-0 protocol and consistency rules of mapping, assignment and sync objects.
    fn check_kind(&self, o: &Obj, v: &[u8], sub0: bool, high: bool, ca: bool) -> Result<(), Abort> {
        let cur0 = self.od.bytes_of(o, o.base, 1)[0];
        // One bounds check per value (not per byte).
        let u32at = |k: usize| {
            let b = &v[1 + 4 * k..5 + 4 * k];
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        };
        let u16at = |k: usize| {
            let b = &v[1 + 2 * k..3 + 2 * k];
            u16::from_le_bytes([b[0], b[1]])
        };
        match o.kind {
            Kind::Plain => Ok(()),
            Kind::RxMap | Kind::TxMap => {
                let dir = if o.kind == Kind::RxMap {
                    Dir::Rx
                } else {
                    Dir::Tx
                };
                if high && !ca && cur0 != 0 {
                    return Err(Abort::SubindexCannotBeWritten);
                }
                let n = v[0] as usize;
                if n > MAX_PDO_ENTRIES || n > o.entries.len() - 1 {
                    return Err(Abort::ValueRangeExceeded);
                }
                if sub0 {
                    let mut bits = 0;
                    for k in 0..n {
                        bits += pdo::check_entry(&self.od, dir, PdoEntry::decode(u32at(k)))?;
                    }
                    if bits > MAX_PD_BYTES * 8 {
                        return Err(Abort::PdoLengthExceeded);
                    }
                } else {
                    for k in 0..o.entries.len() - 1 {
                        let x = u32at(k);
                        if x != 0 {
                            pdo::check_entry(&self.od, dir, PdoEntry::decode(x))?;
                        }
                    }
                }
                Ok(())
            }
            Kind::RxAssign | Kind::TxAssign => {
                let dir = if o.kind == Kind::RxAssign {
                    Dir::Rx
                } else {
                    Dir::Tx
                };
                if high && !ca && cur0 != 0 {
                    return Err(Abort::SubindexCannotBeWritten);
                }
                let n = v[0] as usize;
                if n > MAX_ASSIGN || n > o.entries.len() - 1 {
                    return Err(Abort::ValueRangeExceeded);
                }
                let pdos = match dir {
                    Dir::Rx => self.od.def().rx_pdos,
                    Dir::Tx => self.od.def().tx_pdos,
                };
                let range = if sub0 { n } else { o.entries.len() - 1 };
                let mut bits = 0;
                for k in 0..range {
                    let x = u16at(k);
                    if x == 0 && !sub0 {
                        continue;
                    }
                    if !pdos.iter().any(|p| p.index == x) {
                        return Err(Abort::ParameterIncompatible);
                    }
                    if sub0 {
                        if (0..k).any(|j| u16at(j) == x) {
                            return Err(Abort::ParameterIncompatible);
                        }
                        bits += pdo::pdo_bits(&self.od, dir, x)?;
                    }
                }
                if bits > MAX_PD_BYTES * 8 {
                    return Err(Abort::PdoLengthExceeded);
                }
                Ok(())
            }
            Kind::SyncPar => {
                let mode = u16::from_le_bytes([v[1], v[2]]);
                match SyncMode::from_u16(mode) {
                    Some(m) if self.od.def().sync.supported & m.support_bit() != 0 => Ok(()),
                    _ => Err(Abort::ValueRangeExceeded),
                }
            }
        }
    }

    fn initiate_upload(&mut self, index: u16, sub: u8, ca: bool) -> Result<(), Abort> {
        let (o, size) = self.target(index, sub, ca, false)?;
        // The next segment's toggle bit is clear: `upload_part` flips this one.
        self.upload_part(&o, index, sub, ca, size, 0, true, true);
        Ok(())
    }

    fn upload_segment(&mut self, toggle: bool) {
        let SdoState::Upload {
            index,
            sub,
            ca,
            size,
            sent,
            toggle: t,
        } = self.sdo
        else {
            return self.abort(0, 0, Abort::InvalidCommand);
        };
        if toggle != t {
            return self.abort(index, sub, Abort::ToggleBit);
        }
        let Some(o) = self.od.find(index) else {
            return self.abort(index, sub, Abort::ObjectDoesNotExist);
        };
        self.upload_part(&o, index, sub, ca, size, sent, toggle, false);
    }

    /// Queues the next part of an upload from stream byte `sent`: the initiate response
    /// (`initiate`: command, index, subindex, then 1 to 4 bytes of one entry expedited in the
    /// header's data field, else the size before the data) or an
    /// upload segment (command `toggle`, unused bytes, last; data padded to 7 bytes), the
    /// data read straight into the reply; then the transfer's state, the next segment's
    /// toggle the inverse of `toggle`. One path for both (they were two copies of the read,
    /// the reply and the state).
    #[allow(clippy::too_many_arguments)]
    fn upload_part(
        &mut self,
        o: &Obj,
        index: u16,
        sub: u8,
        ca: bool,
        size: usize,
        sent: usize,
        toggle: bool,
        initiate: bool,
    ) {
        // Expedited: 1 to 4 bytes of one entry in the header's data field.
        let expedited = initiate && !ca && size <= 4 && size > 0;
        let at = if expedited {
            6
        } else if initiate {
            10
        } else {
            3
        };
        let n = (size - sent).min(self.reply_capacity() - at);
        let mut b = [0u8; M];
        self.stream_read(o, sub, ca, sent, &mut b[at..at + n]);
        let last = sent + n == size;
        let (cmd, len) = if initiate {
            b[3..5].copy_from_slice(&index.to_le_bytes());
            b[5] = sub;
            if expedited {
                (0x43 | (((4 - size) as u8) << 2), 10)
            } else {
                b[6..10].copy_from_slice(&(size as u32).to_le_bytes());
                (0x41 | if ca { 0x10 } else { 0 }, 10 + n)
            }
        } else {
            let unused = if n < 7 { (7 - n) as u8 } else { 0 };
            let cmd = (if toggle { 0x10 } else { 0 }) | (unused << 1) | u8::from(last);
            (cmd, 3 + n.max(7))
        };
        coe_head(&mut b, CoeService::SdoResponse, cmd);
        self.queue_reply(MailboxType::Coe, &b[..len]);
        self.sdo = if last {
            SdoState::Idle
        } else {
            SdoState::Upload {
                index,
                sub,
                ca,
                size,
                sent: sent + n,
                toggle: !toggle,
            }
        };
    }

    // ------------------------------------------------------------------ SDO information

    fn info_reply(&mut self, opcode: SdoInfoOpcode, incomplete: bool, left: u16, data: &[u8]) {
        let mut b = [0u8; M];
        let n = COE_HEADER_LEN + SDO_INFO_HEADER_LEN + data.len();
        if n > M {
            return;
        }
        coe_head(
            &mut b,
            CoeService::SdoInformation,
            opcode.code() | if incomplete { 0x80 } else { 0 },
        );
        b[4..6].copy_from_slice(&left.to_le_bytes());
        b[COE_HEADER_LEN + SDO_INFO_HEADER_LEN..n].copy_from_slice(data);
        self.queue_reply(MailboxType::Coe, &b[..n]);
    }

    fn info_error(&mut self, code: Abort) {
        self.info_reply(
            SdoInfoOpcode::Error,
            false,
            0,
            &abort_code(code).to_le_bytes(),
        );
    }

    fn in_list(&self, n: usize, list_type: u16) -> bool {
        let Some(o) = self.od.object_at(n) else {
            return false;
        };
        match list_type {
            od_list_type::ALL => true,
            od_list_type::RX_PDO_MAPPABLE => o.entries.defs().iter().any(|e| e.pdo.rx()),
            od_list_type::TX_PDO_MAPPABLE => o.entries.defs().iter().any(|e| e.pdo.tx()),
            _ => false,
        }
    }

    fn info_request(&mut self, p: &[u8]) {
        let Ok(r) = SdoInfoRef::parse(p) else {
            self.mbx_error(MailboxErrorDetail::SizeTooShort);
            return;
        };
        self.sdo = SdoState::Idle;
        // The three requests decoded here, as `SdoInfoService::parse` decodes them: a board
        // image has no use for its decoding of the responses. Any other opcode, and a
        // request too short for its fields, is a service the stack does not serve.
        let d = r.data;
        let u16at = |i: usize| u16::from_le_bytes([d[i], d[i + 1]]);
        match r.header.opcode {
            SdoInfoOpcode::GetOdListRequest if d.len() >= 2 => {
                let list_type = u16at(0);
                if list_type == od_list_type::LENGTHS {
                    let total = self.od.object_count();
                    let mut w = [0u8; 12];
                    let counts = [
                        0u16,
                        total as u16,
                        (0..total).filter(|&n| self.in_list(n, 2)).count() as u16,
                        (0..total).filter(|&n| self.in_list(n, 3)).count() as u16,
                        0,
                        0,
                    ];
                    for (k, c) in counts.iter().enumerate() {
                        w[2 * k..2 * k + 2].copy_from_slice(&c.to_le_bytes());
                    }
                    self.info_reply(SdoInfoOpcode::GetOdListResponse, false, 0, &w);
                } else if list_type <= od_list_type::SETTINGS {
                    let total = self.od.object_count();
                    let count = (0..total).filter(|&n| self.in_list(n, list_type)).count();
                    let per = (self.reply_capacity() - 6) / 2;
                    let words = count + 1;
                    let frags = words.div_ceil(per).max(1);
                    self.sdo = SdoState::InfoList {
                        list_type,
                        next: 0,
                        left: frags as u16,
                    };
                    self.info_list_fragment(true);
                } else {
                    self.info_error(Abort::UnsupportedAccess);
                }
            }
            SdoInfoOpcode::GetObjectDescriptionRequest if d.len() >= 2 => {
                let index = u16at(0);
                let Some(o) = self.od.find(index) else {
                    return self.info_error(Abort::ObjectDoesNotExist);
                };
                let mut d = [0u8; M];
                let name = o.name.as_bytes();
                let cap = self.reply_capacity() - 6 - 6;
                let nl = name.len().min(cap);
                let dt = match o.code {
                    ObjectCode::Var => o.entries.get(0).map_or(0, |(_, e)| e.dtype.code()),
                    ObjectCode::Array => o.entries.last().map_or(0, |(_, e)| e.dtype.code()),
                    ObjectCode::Record => 0x002A,
                };
                d[0..2].copy_from_slice(&index.to_le_bytes());
                d[2..4].copy_from_slice(&dt.to_le_bytes());
                d[4] = o.max_sub();
                d[5] = o.code.code();
                d[6..6 + nl].copy_from_slice(&name[..nl]);
                self.info_reply(
                    SdoInfoOpcode::GetObjectDescriptionResponse,
                    false,
                    0,
                    &d[..6 + nl],
                );
            }
            SdoInfoOpcode::GetEntryDescriptionRequest if d.len() >= 4 => {
                let (index, subindex, value_info) = (u16at(0), d[2], d[3]);
                let Some(o) = self.od.find(index) else {
                    return self.info_error(Abort::ObjectDoesNotExist);
                };
                let Some((_, e, _)) = o.entry(subindex) else {
                    return self.info_error(Abort::SubindexDoesNotExist);
                };
                let mut d = [0u8; M];
                let cap = (self.reply_capacity() - 6).min(M);
                let (vi, mut at) = self.value_info(&o, subindex, e, value_info, &mut d[..cap]);
                let mut acc = o.access(e).0;
                if e.pdo.rx() {
                    acc |= 0x40;
                }
                if e.pdo.tx() {
                    acc |= 0x80;
                }
                d[0..2].copy_from_slice(&index.to_le_bytes());
                d[2] = subindex;
                d[3] = vi;
                d[4..6].copy_from_slice(&e.dtype.code().to_le_bytes());
                d[6..8].copy_from_slice(&e.bits.to_le_bytes());
                d[8..10].copy_from_slice(&acc.to_le_bytes());
                at += o.entries.name_into(subindex, e, &mut d[at..cap]);
                self.info_reply(
                    SdoInfoOpcode::GetEntryDescriptionResponse,
                    false,
                    0,
                    &d[..at],
                );
            }
            _ => self.mbx_error(MailboxErrorDetail::ServiceNotSupported),
        }
    }

    /// Fills the optional fields of an entry description after the 10 fixed bytes of `d`
    /// as requested by `req` (ETG.1000.6 value info: 0x08 unit type (UNSIGNED32, ETG.1004),
    /// 0x10 default, 0x20 minimum, 0x40 maximum value, each in the entry's storage length);
    /// returns the value info actually served (strings have no minimum/maximum; a field
    /// that does not fit the reply is left out) and the end offset.
    fn value_info(&self, o: &Obj, sub: u8, e: &EntryDef, req: u8, d: &mut [u8]) -> (u8, usize) {
        let len = e.storage_len();
        let mut vi = 0u8;
        let mut at = 10;
        if req & 0x08 != 0 && at + 4 <= d.len() {
            d[at..at + 4].copy_from_slice(&e.limits.unit.to_le_bytes());
            at += 4;
            vi |= 0x08;
        }
        if req & 0x10 != 0 && at + len <= d.len() {
            self.od.default_of(o, sub, e, &mut d[at..at + len]);
            at += len;
            vi |= 0x10;
        }
        if let Some((min, max)) = value_limits(e) {
            for (bit, v) in [(0x20u8, min), (0x40, max)] {
                if req & bit != 0 && at + len <= d.len() {
                    let b = v.to_le_bytes();
                    let n = len.min(8);
                    d[at..at + len].fill(0);
                    d[at..at + n].copy_from_slice(&b[..n]);
                    at += len;
                    vi |= bit;
                }
            }
        }
        (vi, at)
    }

    fn info_list_fragment(&mut self, first: bool) {
        let SdoState::InfoList {
            list_type,
            next,
            left,
        } = self.sdo
        else {
            return;
        };
        let per = (self.reply_capacity() - 6) / 2;
        let mut d = [0u8; M];
        let mut w = 0;
        if first {
            d[0..2].copy_from_slice(&list_type.to_le_bytes());
            w = 1;
        }
        let total = self.od.object_count();
        let mut n = next;
        while n < total && w < per {
            if self.in_list(n, list_type) {
                if let Some(o) = self.od.object_at(n) {
                    d[2 * w..2 * w + 2].copy_from_slice(&o.index.to_le_bytes());
                    w += 1;
                }
            }
            n += 1;
        }
        while n < total && !self.in_list(n, list_type) {
            n += 1;
        }
        let left = left.saturating_sub(1);
        let more = n < total;
        self.info_reply(SdoInfoOpcode::GetOdListResponse, more, left, &d[..2 * w]);
        self.sdo = if more {
            SdoState::InfoList {
                list_type,
                next: n,
                left,
            }
        } else {
            SdoState::Idle
        };
    }

    /// Produces the next fragment of a fragmented reply; true if one was queued.
    pub(crate) fn sdo_continue(&mut self) -> bool {
        if matches!(self.sdo, SdoState::InfoList { .. }) {
            self.info_list_fragment(false);
            return true;
        }
        false
    }
}
