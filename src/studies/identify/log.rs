//! Reading and writing joint logs (the format is described in the parent module).

use super::*;

/// The parsed header: the name of every field and, for known columns, its index in
/// [`LOG_COLUMNS`].
pub(super) struct Header {
    names: Vec<String>,
    slots: Vec<Option<usize>>,
}

pub(super) fn parse_header(text: &str, line: usize) -> Result<Header, IdentifyError> {
    let mut names = Vec::new();
    let mut slots = Vec::new();
    let mut seen = [false; LOG_COLUMNS.len()];
    for (position, raw) in text.split(',').enumerate() {
        let name = raw.trim();
        if name.is_empty() {
            return Err(IdentifyError::BadHeader {
                line,
                message: format!("column {} has an empty name", position + 1),
            });
        }
        if names.iter().any(|n| n == name) {
            return Err(IdentifyError::BadHeader {
                line,
                message: format!("column `{name}` appears twice"),
            });
        }
        let slot = LOG_COLUMNS.iter().position(|c| *c == name);
        match slot {
            Some(index) => seen[index] = true,
            None if name.starts_with(EXTRA_COLUMN_PREFIX) => {}
            None => {
                return Err(IdentifyError::UnknownColumn {
                    line,
                    column: name.to_owned(),
                });
            }
        }
        names.push(name.to_owned());
        slots.push(slot);
    }
    if let Some(missing) = seen.iter().position(|s| !s) {
        return Err(IdentifyError::MissingColumn {
            line,
            column: LOG_COLUMNS[missing],
        });
    }
    Ok(Header { names, slots })
}

pub(super) fn parse_row(text: &str, line: usize, header: &Header) -> Result<LogRow, IdentifyError> {
    let expected = header.names.len();
    let mut row = LogRow::default();
    let mut found = 0;
    for (index, raw) in text.split(',').enumerate() {
        found = index + 1;
        if index >= expected {
            return Err(IdentifyError::ExtraField {
                line,
                found: text.split(',').count(),
                expected,
            });
        }
        let Some(slot) = header.slots[index] else {
            continue;
        };
        let value = raw.trim();
        let parsed: f64 = value.parse().map_err(|_| IdentifyError::BadNumber {
            line,
            column: header.names[index].clone(),
            value: value.to_owned(),
        })?;
        if !parsed.is_finite() {
            return Err(IdentifyError::NonFinite {
                line,
                column: header.names[index].clone(),
                value: value.to_owned(),
            });
        }
        *row.field_mut(slot) = parsed;
    }
    if found < expected {
        return Err(IdentifyError::MissingField {
            line,
            column: header.names[found].clone(),
            found,
            expected,
        });
    }
    Ok(row)
}

/// Reads a log in [the log format](self#log-format). A log with a header and no sample is valid
/// (and gives no row).
pub fn read_log<R: BufRead>(mut reader: R) -> Result<Vec<LogRow>, IdentifyError> {
    let mut buffer = String::new();
    let mut line = 0;
    let mut header: Option<Header> = None;
    let mut rows = Vec::new();
    loop {
        buffer.clear();
        let read = reader
            .read_line(&mut buffer)
            .map_err(|source| IdentifyError::Read {
                line: line + 1,
                source,
            })?;
        if read == 0 {
            break;
        }
        line += 1;
        let text = buffer.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        match &header {
            None => header = Some(parse_header(text, line)?),
            Some(h) => rows.push(parse_row(text, line, h)?),
        }
    }
    if header.is_none() {
        return Err(IdentifyError::MissingHeader);
    }
    Ok(rows)
}

/// The first bytes of every MCAP file.
const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Opens and reads a log file: the CSV log (see [`read_log`]), or a board's MCAP recording
/// (`vic-board --record FILE.mcap`, told by its magic bytes), whose joint 0 gives the same
/// columns. Ticks whose nine values are not all finite are skipped, as the CSV recording
/// writes them as comments.
pub fn read_log_file(path: impl AsRef<Path>) -> Result<Vec<LogRow>, IdentifyError> {
    let path = path.as_ref();
    let open_error = |source| IdentifyError::Open {
        path: path.to_owned(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(open_error)?;
    let mut magic = [0u8; 8];
    let is_mcap = match io::Read::read_exact(&mut file, &mut magic) {
        Ok(()) => &magic == MCAP_MAGIC,
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => false,
        Err(e) => return Err(open_error(e)),
    };
    if is_mcap {
        return Ok(rows_of_recording(&vic_rt::record::read_board_mcap(path)?));
    }
    io::Seek::rewind(&mut file).map_err(open_error)?;
    read_log(io::BufReader::new(file))
}

/// Joint 0 of every tick of a board recording whose log columns are finite.
fn rows_of_recording(rec: &vic_rt::record::BoardRecording) -> Vec<LogRow> {
    let t0 = rec.samples.first().map_or(0, |s| s.deadline_ns);
    rec.samples
        .iter()
        .map(|s| LogRow {
            t: s.deadline_ns.saturating_sub(t0) as f64 * 1e-9,
            q: s.q[0],
            qd: s.qd[0],
            qdd: s.qdd[0],
            tau_ff: s.tau_ff[0],
            stiffness: s.stiffness[0],
            damping: s.damping[0],
            q_d: s.q_d[0],
            qd_d: s.qd_d[0],
        })
        .filter(|r| {
            [
                r.q,
                r.qd,
                r.qdd,
                r.tau_ff,
                r.stiffness,
                r.damping,
                r.q_d,
                r.qd_d,
            ]
            .iter()
            .all(|v| v.is_finite())
        })
        .collect()
}

/// Writes the header line [`LOG_HEADER`].
pub(crate) fn write_header<W: Write + ?Sized>(writer: &mut W) -> io::Result<()> {
    writer.write_all(LOG_HEADER.as_bytes())?;
    writer.write_all(b"\n")
}

/// Writes one sample, in the column order of [`LOG_HEADER`], with the shortest representation
/// that reads back bit-identically. Does not allocate (the formatting goes straight to
/// `writer`; wrap it in a `BufWriter` on a recording thread). Non-finite values are written as
/// `NaN`/`inf` but [`read_log`] rejects them.
pub(crate) fn write_row<W: Write + ?Sized>(writer: &mut W, row: &LogRow) -> io::Result<()> {
    writeln!(
        writer,
        "{},{},{},{},{},{},{},{},{}",
        row.t, row.q, row.qd, row.qdd, row.tau_ff, row.stiffness, row.damping, row.q_d, row.qd_d
    )
}

/// Writes a header and all rows.
pub fn write_log<W: Write + ?Sized>(writer: &mut W, rows: &[LogRow]) -> io::Result<()> {
    write_header(writer)?;
    for row in rows {
        write_row(writer, row)?;
    }
    Ok(())
}
