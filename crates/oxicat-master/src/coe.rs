//! CoE over the slave's mailbox SyncManagers (SM0 out, SM1 in), driven with plain FPRD/FPWR
//! datagrams: SDO upload/download (expedited, normal, segmented) and SDO information.

use std::time::{Duration, Instant};

use oxicat_wire::coe::{
    write_sdo, write_sdo_segment, CoeHeader, CoeService, SdoAbortCode, SdoHeader, SdoInfoHeader,
    SdoInfoOpcode, SdoInfoRef, SdoInfoService, SdoRef, SdoRequestCommand, SdoResponseCommand,
    COE_HEADER_LEN, SDO_INFO_HEADER_LEN,
};
use oxicat_wire::mailbox::{MailboxHeader, MailboxRef, MailboxType, MAILBOX_HEADER_LEN};

use crate::{Master, MasterError};

/// SM0/SM1 of a slave as configured for the mailbox.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Mbx {
    pub(crate) out_start: u16,
    pub(crate) out_len: u16,
    pub(crate) in_start: u16,
    pub(crate) in_len: u16,
}

/// The description of one object (SDO information).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectDesc {
    /// Index.
    pub index: u16,
    /// Data type code.
    pub data_type: u16,
    /// Highest subindex.
    pub max_sub: u8,
    /// Object code (7 VAR, 8 ARRAY, 9 RECORD).
    pub object_code: u8,
    /// Name.
    pub name: String,
    /// Entries (subindex 0..=max_sub that the slave describes).
    pub entries: Vec<EntryDesc>,
}

/// The description of one entry (SDO information).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EntryDesc {
    /// Subindex.
    pub sub: u8,
    /// Data type code.
    pub data_type: u16,
    /// Bit length.
    pub bits: u16,
    /// Object access flags (bits 0..5 read/write in PREOP/SAFEOP/OP, 6 RxPDO, 7 TxPDO).
    pub access: u16,
    /// Unit (ETG.1004 code) if the slave gave one.
    pub unit: Option<u32>,
    /// Name.
    pub name: String,
}

impl EntryDesc {
    /// The access as the IgH tool prints it: read and write for PREOP, SAFEOP and OP
    /// (`rwr-r-`), from the SDO information access bits (0..2 read, 3..5 write).
    pub fn igh_access(&self) -> String {
        (0..3)
            .flat_map(|state| {
                [
                    if self.access & (1 << state) != 0 {
                        'r'
                    } else {
                        '-'
                    },
                    if self.access & (8 << state) != 0 {
                        'w'
                    } else {
                        '-'
                    },
                ]
            })
            .collect()
    }

    /// `rw`, `ro`, `wo` from the access flags (for PRE-OP … OP together).
    pub fn access_text(&self) -> &'static str {
        let r = self.access & 0x07 != 0;
        let w = self.access & 0x38 != 0;
        match (r, w) {
            (true, true) => "rw",
            (true, false) => "ro",
            (false, true) => "wo",
            _ => "--",
        }
    }
}

/// A CoE data type code as the IgH tool names it in `sdos` (`uint32`, `string`, …;
/// `type 0x0029` for one it has no name for).
pub fn igh_type_name(code: u16) -> String {
    let n = match code {
        0x0001 => "bool",
        0x0002 => "int8",
        0x0003 => "int16",
        0x0004 => "int32",
        0x0005 => "uint8",
        0x0006 => "uint16",
        0x0007 => "uint32",
        0x0008 => "float",
        0x0009 => "string",
        0x000A => "octet_string",
        0x000B => "unicode_string",
        0x0010 => "int24",
        0x0011 => "double",
        0x0012 => "int40",
        0x0013 => "int48",
        0x0014 => "int56",
        0x0015 => "int64",
        0x0016 => "uint24",
        0x0018 => "uint40",
        0x0019 => "uint48",
        0x001A => "uint56",
        0x001B => "uint64",
        c => return format!("type 0x{c:04x}"),
    };
    n.to_string()
}

/// A CoE data type code as its ETG name.
pub fn type_name(code: u16) -> String {
    oxicat_wire::datatype::by_code(code)
        .map_or_else(|| format!("DT{code:04X}"), |d| d.name.to_string())
}

fn mbx_err(position: usize, what: impl Into<String>) -> MasterError {
    MasterError::Mailbox {
        position,
        what: what.into(),
    }
}

impl Master {
    async fn mailbox(&self, position: usize) -> Result<Mbx, MasterError> {
        // A slave in INIT has no mailbox service (its SMs may still look configured).
        let st = self.al_status_async(position).await?;
        if matches!(st.state(), Some(crate::AlState::Init) | None) {
            return Err(mbx_err(
                position,
                format!(
                    "the slave is in {st}; its mailbox works from PREOP on (`oxicat states preop`)"
                ),
            ));
        }
        match self.mailbox_as_is(position).await {
            Err(MasterError::NoCoe(_)) => {}
            r => return r,
        }
        // SM0/SM1 not configured (another master cleared them): configure them from the
        // SII, leaving the AL state as it is.
        self.configure_mailbox(position, false).await?;
        match self.mailbox_as_is(position).await {
            Err(MasterError::NoCoe(_)) => {
                let b = self.fprd(position, 0x0800, 16).await?;
                Err(mbx_err(
                    position,
                    format!(
                        "SM0/SM1 are not set up for a mailbox (0x0800..0x080F: {})",
                        crate::value::hex(&b)
                    ),
                ))
            }
            r => r,
        }
    }

    async fn mailbox_as_is(&self, position: usize) -> Result<Mbx, MasterError> {
        let b = self.fprd(position, 0x0800, 16).await?;
        let u = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let m = Mbx {
            out_start: u(0),
            out_len: u(2),
            in_start: u(8),
            in_len: u(10),
        };
        let enabled = b[6] & 1 != 0 && b[14] & 1 != 0;
        if !enabled || m.out_len < 16 || m.in_len < 16 {
            return Err(MasterError::NoCoe(position));
        }
        Ok(m)
    }

    /// The mailbox counter of this master's next message to the slave at `position`.
    ///
    /// ETG.1000.4 (mailbox header, `Cnt`): 0 is the start value, then 1..7 and after 7
    /// again 1; a slave drops a message whose counter equals that of the message before
    /// (a repeat), except 0. A master cannot know the counter another master (an earlier
    /// `oxicat` command) used last, so its first message to a slave carries 0, which no
    /// slave takes for a repeat; then 2..=7 (ethercrab's own mailbox traffic in the cyclic
    /// verbs starts at 1, so its first message never repeats ours).
    pub(crate) fn next_counter(&self, position: usize) -> u8 {
        let mut all = self.mbx_counter.borrow_mut();
        if all.len() <= position {
            all.resize(position + 1, None);
        }
        let n = match all[position] {
            None => 0,
            Some(c) if (2..7).contains(&c) => c + 1,
            Some(_) => 2,
        };
        all[position] = Some(n);
        n
    }

    /// Sends one CoE message (`payload` = CoE header + data) and returns the CoE reply.
    async fn coe_exchange(&self, position: usize, payload: &[u8]) -> Result<Vec<u8>, MasterError> {
        let m = self.mailbox(position).await?;
        // Drop a stale reply.
        let st = self.fprd(position, 0x080D, 1).await?;
        if st[0] & 0x08 != 0 {
            self.fprd(position, m.in_start, m.in_len).await?;
        }
        let mut first = true;
        loop {
            let counter = self.next_counter(position);
            self.mbx_send(position, &m, MailboxType::Coe, payload, counter)
                .await?;
            // The first try waits briefly: a message dropped as a repeat (same counter as the
            // slave's last one) is sent again with the next counter.
            let wait = if first {
                self.options.mailbox_timeout.min(Duration::from_millis(300))
            } else {
                self.options.mailbox_timeout
            };
            match self
                .mbx_receive(position, &m, MailboxType::Coe, wait)
                .await?
            {
                Some(r) => return Ok(r),
                None if first => first = false,
                None => {
                    return Err(MasterError::NotAnswering {
                        position,
                        what: "no mailbox reply".into(),
                    })
                }
            }
        }
    }

    /// The slave's mailbox SyncManagers (for the other mailbox protocols, e.g. FoE).
    pub(crate) async fn mbx_for(&self, position: usize) -> Result<Mbx, MasterError> {
        self.mailbox(position).await
    }

    /// Writes one message of type `t` into SM0 once it is empty.
    pub(crate) async fn mbx_send(
        &self,
        position: usize,
        m: &Mbx,
        t: MailboxType,
        payload: &[u8],
        counter: u8,
    ) -> Result<(), MasterError> {
        if MAILBOX_HEADER_LEN + payload.len() > m.out_len as usize {
            return Err(mbx_err(position, "request longer than the mailbox"));
        }
        let deadline = Instant::now() + self.options.mailbox_timeout;
        // Wait for SM0 to be empty.
        loop {
            let st = self.fprd(position, 0x0805, 1).await?;
            if st[0] & 0x08 == 0 {
                break;
            }
            if Instant::now() > deadline {
                return Err(mbx_err(
                    position,
                    "the slave does not empty its receive mailbox",
                ));
            }
            self.pause().await;
        }
        let mut buf = vec![0u8; m.out_len as usize];
        let h = MailboxHeader::new(payload.len() as u16, 0, t, counter);
        h.write(&mut buf)
            .map_err(|e| mbx_err(position, format!("{e}")))?;
        buf[MAILBOX_HEADER_LEN..MAILBOX_HEADER_LEN + payload.len()].copy_from_slice(payload);
        self.fpwr(position, m.out_start, &buf).await
    }

    /// Waits up to `wait` for a reply of type `t` in SM1 (CoE emergencies and other types
    /// are logged and dropped); `None` if none came.
    pub(crate) async fn mbx_receive(
        &self,
        position: usize,
        m: &Mbx,
        t: MailboxType,
        wait: Duration,
    ) -> Result<Option<Vec<u8>>, MasterError> {
        let deadline = Instant::now() + wait;
        loop {
            let st = self.fprd(position, 0x080D, 1).await?;
            if st[0] & 0x08 != 0 {
                let b = self.fprd(position, m.in_start, m.in_len).await?;
                let r = MailboxRef::parse(&b)
                    .map_err(|e| mbx_err(position, format!("bad mailbox header: {e}")))?;
                match r.header.mailbox_type {
                    x if x == t && t != MailboxType::Coe => {
                        return Ok(Some(r.payload.to_vec()));
                    }
                    MailboxType::Coe if t == MailboxType::Coe => {
                        let coe = CoeHeader::parse(r.payload)
                            .map_err(|e| mbx_err(position, format!("bad CoE header: {e}")))?;
                        if coe.service == CoeService::Emergency {
                            log::warn!("slave {position}: emergency {:02x?}", r.payload);
                            continue;
                        }
                        return Ok(Some(r.payload.to_vec()));
                    }
                    MailboxType::Error => {
                        let d = r
                            .payload
                            .get(2..4)
                            .map(|b| u16::from_le_bytes([b[0], b[1]]));
                        return Err(mbx_err(
                            position,
                            format!("mailbox error reply, detail 0x{:04X}", d.unwrap_or(0)),
                        ));
                    }
                    other => {
                        log::warn!("slave {position}: ignoring a {other:?} mailbox message");
                        continue;
                    }
                }
            }
            if Instant::now() > deadline {
                return Ok(None);
            }
            self.pause().await;
        }
    }

    /// Reads object `index:sub` of the slave at `position` (SDO upload).
    pub fn sdo_upload(&self, position: usize, index: u16, sub: u8) -> Result<Vec<u8>, MasterError> {
        self.runner
            .block_on(self.sdo_upload_async(position, index, sub))
    }

    /// Writes `data` to object `index:sub` of the slave at `position` (SDO download).
    pub fn sdo_download(
        &self,
        position: usize,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), MasterError> {
        self.runner
            .block_on(self.sdo_download_async(position, index, sub, data))
    }

    fn check_abort(
        position: usize,
        index: u16,
        sub: u8,
        r: &SdoRef<'_>,
    ) -> Result<SdoResponseCommand, MasterError> {
        if r.is_request() {
            // An abort request from the server.
            if r.command >> 5 == 4 {
                let code = r.abort_code().unwrap_or(SdoAbortCode::GeneralError);
                return Err(MasterError::SdoAbort {
                    position,
                    index,
                    sub,
                    code,
                });
            }
            return Err(mbx_err(
                position,
                "SDO request where a response was expected",
            ));
        }
        let cmd = SdoResponseCommand::from_u8(r.command)
            .map_err(|e| mbx_err(position, format!("bad SDO command: {e}")))?;
        if cmd == SdoResponseCommand::Abort {
            let code = r.abort_code().unwrap_or(SdoAbortCode::GeneralError);
            return Err(MasterError::SdoAbort {
                position,
                index,
                sub,
                code,
            });
        }
        Ok(cmd)
    }

    pub(crate) async fn sdo_upload_async(
        &self,
        position: usize,
        index: u16,
        sub: u8,
    ) -> Result<Vec<u8>, MasterError> {
        let mut req = [0u8; 16];
        let n = write_sdo(
            &mut req,
            CoeService::SdoRequest,
            &SdoHeader {
                command: 0x40,
                index,
                subindex: sub,
            },
            [0; 4],
            &[],
        )
        .map_err(|e| mbx_err(position, format!("{e}")))?;
        let reply = self.coe_exchange(position, &req[..n]).await?;
        let r =
            SdoRef::parse(&reply).map_err(|e| mbx_err(position, format!("bad SDO reply: {e}")))?;
        let cmd = Self::check_abort(position, index, sub, &r)?;
        let bad = |e| mbx_err(position, format!("bad SDO reply: {e}"));
        match cmd {
            SdoResponseCommand::InitiateUpload {
                expedited: true, ..
            } => Ok(r.expedited_data().map_err(bad)?.to_vec()),
            SdoResponseCommand::InitiateUpload {
                expedited: false, ..
            } => {
                let (size, data) = r.normal_data().map_err(bad)?;
                let size = size as usize;
                let mut out = data[..data.len().min(size)].to_vec();
                let mut toggle = false;
                while out.len() < size {
                    let mut seg = [0u8; 16];
                    let n = write_sdo_segment(
                        &mut seg,
                        CoeService::SdoRequest,
                        SdoRequestCommand::UploadSegment { toggle }
                            .to_u8()
                            .map_err(bad)?,
                        &[0; 7],
                    )
                    .map_err(bad)?;
                    let reply = self.coe_exchange(position, &seg[..n]).await?;
                    let r = SdoRef::parse(&reply).map_err(bad)?;
                    match Self::check_abort(position, index, sub, &r)? {
                        SdoResponseCommand::UploadSegment {
                            last, toggle: t, ..
                        } => {
                            if t != toggle {
                                return Err(mbx_err(position, "SDO segment toggle bit wrong"));
                            }
                            let d = r.segment_data().map_err(bad)?;
                            let take = d.len().min(size - out.len());
                            out.extend_from_slice(&d[..take]);
                            if last {
                                break;
                            }
                        }
                        other => return Err(mbx_err(position, format!("unexpected {other:?}"))),
                    }
                    toggle = !toggle;
                }
                Ok(out)
            }
            other => Err(mbx_err(
                position,
                format!("unexpected SDO response {other:?}"),
            )),
        }
    }

    pub(crate) async fn sdo_download_async(
        &self,
        position: usize,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), MasterError> {
        let bad = |e| mbx_err(position, format!("SDO: {e}"));
        let hdr = |command| SdoHeader {
            command,
            index,
            subindex: sub,
        };
        let mut req = vec![0u8; 16 + data.len()];
        let m = self.mailbox(position).await?;
        // Mailbox header + CoE + SDO header + size.
        let room = (m.out_len as usize).saturating_sub(MAILBOX_HEADER_LEN + 10);
        let (n, rest): (usize, &[u8]) = if data.len() <= 4 {
            let mut d = [0u8; 4];
            d[..data.len()].copy_from_slice(data);
            let cmd = SdoRequestCommand::InitiateDownload {
                size_indicated: true,
                expedited: true,
                unused: (4 - data.len()) as u8,
                complete_access: false,
            }
            .to_u8()
            .map_err(bad)?;
            (
                write_sdo(&mut req, CoeService::SdoRequest, &hdr(cmd), d, &[]).map_err(bad)?,
                &[],
            )
        } else {
            let first = data.len().min(room);
            let cmd = SdoRequestCommand::InitiateDownload {
                size_indicated: true,
                expedited: false,
                unused: 0,
                complete_access: false,
            }
            .to_u8()
            .map_err(bad)?;
            (
                write_sdo(
                    &mut req,
                    CoeService::SdoRequest,
                    &hdr(cmd),
                    (data.len() as u32).to_le_bytes(),
                    &data[..first],
                )
                .map_err(bad)?,
                &data[first..],
            )
        };
        let reply = self.coe_exchange(position, &req[..n]).await?;
        let r = SdoRef::parse(&reply).map_err(bad)?;
        match Self::check_abort(position, index, sub, &r)? {
            SdoResponseCommand::InitiateDownload => {}
            other => {
                return Err(mbx_err(
                    position,
                    format!("unexpected SDO response {other:?}"),
                ))
            }
        }
        // Segments: mailbox header + CoE header + command byte.
        let seg_room = (m.out_len as usize).saturating_sub(MAILBOX_HEADER_LEN + 3);
        let mut toggle = false;
        let mut rest = rest;
        while !rest.is_empty() {
            let k = rest.len().min(seg_room);
            let last = k == rest.len();
            let unused = if k < 7 { (7 - k) as u8 } else { 0 };
            let cmd = SdoRequestCommand::DownloadSegment {
                toggle,
                last,
                unused,
            }
            .to_u8()
            .map_err(bad)?;
            let mut seg = vec![0u8; k.max(7) + 3];
            let n = write_sdo_segment(&mut seg, CoeService::SdoRequest, cmd, &rest[..k])
                .map_err(bad)?;
            let reply = self.coe_exchange(position, &seg[..n]).await?;
            let r = SdoRef::parse(&reply).map_err(bad)?;
            match Self::check_abort(position, index, sub, &r)? {
                SdoResponseCommand::DownloadSegment { toggle: t } if t == toggle => {}
                other => {
                    return Err(mbx_err(
                        position,
                        format!("unexpected SDO response {other:?}"),
                    ))
                }
            }
            rest = &rest[k..];
            toggle = !toggle;
        }
        Ok(())
    }

    /// Sends an SDO information request and gathers all fragments of the reply (service
    /// data of each fragment concatenated; for the OD list without the repeated list type).
    async fn sdo_info(
        &self,
        position: usize,
        service: SdoInfoService<'_>,
        index: u16,
        sub: u8,
    ) -> Result<(SdoInfoOpcode, Vec<u8>), MasterError> {
        let bad = |e| mbx_err(position, format!("SDO information: {e}"));
        let mut req = [0u8; 32];
        CoeHeader::new(CoeService::SdoInformation)
            .write(&mut req)
            .map_err(bad)?;
        SdoInfoHeader {
            opcode: service.opcode(),
            incomplete: false,
            reserved: 0,
            fragments_left: 0,
        }
        .write(&mut req[COE_HEADER_LEN..])
        .map_err(bad)?;
        let n = service
            .write(&mut req[COE_HEADER_LEN + SDO_INFO_HEADER_LEN..])
            .map_err(bad)?;
        let total = COE_HEADER_LEN + SDO_INFO_HEADER_LEN + n;
        let mut reply = self.coe_exchange(position, &req[..total]).await?;
        let mut data = Vec::new();
        let mut opcode;
        let m = self.mailbox(position).await?;
        loop {
            let r = SdoInfoRef::parse(&reply).map_err(bad)?;
            opcode = r.header.opcode;
            if let SdoInfoOpcode::Error = opcode {
                let code = match r.service() {
                    Ok(SdoInfoService::Error { code }) => code,
                    _ => SdoAbortCode::GeneralError,
                };
                return Err(MasterError::SdoAbort {
                    position,
                    index,
                    sub,
                    code,
                });
            }
            data.extend_from_slice(r.data);
            if !r.header.incomplete {
                break;
            }
            // The next fragment comes without a new request.
            reply = self
                .mbx_receive(position, &m, MailboxType::Coe, self.options.mailbox_timeout)
                .await?
                .ok_or_else(|| MasterError::NotAnswering {
                    position,
                    what: "SDO information fragment missing".into(),
                })?;
        }
        Ok((opcode, data))
    }

    /// The object list of the slave (SDO information, list type "all").
    pub fn sdo_list(&self, position: usize) -> Result<Vec<u16>, MasterError> {
        self.runner.block_on(async {
            let (_, d) = self
                .sdo_info(
                    position,
                    SdoInfoService::GetOdListRequest {
                        list_type: oxicat_wire::coe::od_list_type::ALL,
                    },
                    0,
                    0,
                )
                .await?;
            let words: Vec<u16> = d
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect();
            // The first word is the list type.
            Ok(words.into_iter().skip(1).collect())
        })
    }

    /// The description of object `index` and of each of its entries.
    pub fn sdo_describe(&self, position: usize, index: u16) -> Result<ObjectDesc, MasterError> {
        self.runner
            .block_on(self.sdo_describe_async(position, index))
    }

    pub(crate) async fn sdo_describe_async(
        &self,
        position: usize,
        index: u16,
    ) -> Result<ObjectDesc, MasterError> {
        let (_, d) = self
            .sdo_info(
                position,
                SdoInfoService::GetObjectDescriptionRequest { index },
                index,
                0,
            )
            .await?;
        let o = match SdoInfoService::parse(SdoInfoOpcode::GetObjectDescriptionResponse, &d) {
            Ok(SdoInfoService::GetObjectDescriptionResponse {
                index,
                data_type,
                max_subindex,
                object_code,
                name,
            }) => ObjectDesc {
                index,
                data_type,
                max_sub: max_subindex,
                object_code,
                name: String::from_utf8_lossy(name).into_owned(),
                entries: Vec::new(),
            },
            _ => return Err(mbx_err(position, "bad object description")),
        };
        let mut o = o;
        let last = if o.object_code == 7 { 0 } else { o.max_sub };
        for sub in 0..=last {
            match self.sdo_entry_async(position, index, sub).await {
                Ok(e) => o.entries.push(e),
                Err(MasterError::SdoAbort { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        Ok(o)
    }

    async fn sdo_entry_async(
        &self,
        position: usize,
        index: u16,
        sub: u8,
    ) -> Result<EntryDesc, MasterError> {
        // Value info: unit type (0x08).
        let (_, d) = self
            .sdo_info(
                position,
                SdoInfoService::GetEntryDescriptionRequest {
                    index,
                    subindex: sub,
                    value_info: 0x08,
                },
                index,
                sub,
            )
            .await?;
        match SdoInfoService::parse(SdoInfoOpcode::GetEntryDescriptionResponse, &d) {
            Ok(SdoInfoService::GetEntryDescriptionResponse {
                subindex,
                value_info,
                data_type,
                bit_length,
                object_access,
                data,
                ..
            }) => {
                let (unit, name) = if value_info & 0x08 != 0 && data.len() >= 4 {
                    (
                        Some(u32::from_le_bytes([data[0], data[1], data[2], data[3]])),
                        &data[4..],
                    )
                } else {
                    (None, data)
                };
                Ok(EntryDesc {
                    sub: subindex,
                    data_type,
                    bits: bit_length,
                    access: object_access,
                    unit,
                    name: String::from_utf8_lossy(name).into_owned(),
                })
            }
            _ => Err(mbx_err(position, "bad entry description")),
        }
    }
}
