//! `vic.read_mcap`: every channel of an MCAP file as columns. vic's recordings (`vic-board
//! --record`, `vic record`) write JSON messages; each field becomes a column (nested objects as
//! `outer.inner`, per-joint arrays as 2-D columns), beside the messages' `log_time`,
//! `publish_time` [ns] and `sequence`. Messages of another encoding keep their bytes in `data`.

use crate::convert::json_to_py;
use crate::errors::{Failure, detached};
use pyo3::IntoPyObjectExt;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyList, PyTuple};
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Largest file read (it is read whole): the board reader's limit.
const MAX_FILE_BYTES: u64 = 2 << 30;

/// The first bytes of every MCAP file (and its last).
const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// One field of one message.
#[derive(Debug, Clone)]
enum Cell {
    Null,
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    Str(String),
    /// An array of numbers (`null`: a number that was not finite).
    Numbers(Vec<Option<f64>>),
    /// Anything else, as it was.
    Other(Value),
}

impl Cell {
    fn of(v: Value) -> Cell {
        match v {
            Value::Null => Cell::Null,
            Value::Bool(b) => Cell::Bool(b),
            Value::Number(n) => {
                if let Some(i) = n.as_i64() {
                    Cell::Int(i)
                } else if let Some(u) = n.as_u64() {
                    Cell::UInt(u)
                } else {
                    Cell::Float(n.as_f64().unwrap_or(f64::NAN))
                }
            }
            Value::String(s) => Cell::Str(s),
            Value::Array(a) if a.iter().all(|x| x.is_number() || x.is_null()) => {
                Cell::Numbers(a.iter().map(Value::as_f64).collect())
            }
            other => Cell::Other(other),
        }
    }
}

/// The columns of one channel.
#[derive(Default)]
struct Channel {
    encoding: String,
    schema: String,
    rows: usize,
    log_time: Vec<u64>,
    publish_time: Vec<u64>,
    sequence: Vec<u64>,
    columns: Vec<(String, Vec<Cell>)>,
    index: HashMap<String, usize>,
    data: Vec<Vec<u8>>,
}

impl Channel {
    fn set(&mut self, name: String, cell: Cell) {
        let i = match self.index.get(&name) {
            Some(&i) => i,
            None => {
                self.columns
                    .push((name.clone(), vec![Cell::Null; self.rows]));
                self.index.insert(name, self.columns.len() - 1);
                self.columns.len() - 1
            }
        };
        let col = &mut self.columns[i].1;
        if col.len() == self.rows + 1 {
            // The same name twice in one message (`a.b` beside an object `a` with `b`): the last.
            col[self.rows] = cell;
        } else {
            col.push(cell);
        }
    }

    fn flatten(&mut self, prefix: &str, object: serde_json::Map<String, Value>) {
        for (k, v) in object {
            let name = if prefix.is_empty() {
                k
            } else {
                format!("{prefix}.{k}")
            };
            match v {
                Value::Object(inner) => self.flatten(&name, inner),
                v => self.set(name, Cell::of(v)),
            }
        }
    }

    /// Ends a row: the columns this message did not set get a null.
    fn end_row(&mut self) {
        self.rows += 1;
        for (_, col) in &mut self.columns {
            if col.len() < self.rows {
                col.push(Cell::Null);
            }
        }
    }
}

fn read(path: &Path) -> Result<Vec<(String, Channel)>, String> {
    let shown = path.display();
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{shown}: cannot read: {e}"))?
        .len();
    if len > MAX_FILE_BYTES {
        return Err(format!(
            "{shown}: {len} bytes, larger than the {MAX_FILE_BYTES} bytes read at once"
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("{shown}: cannot read: {e}"))?;
    if !bytes.starts_with(MAGIC) {
        return Err(format!(
            "{shown}: not an MCAP file (it does not start with MCAP's magic bytes)"
        ));
    }
    let stream =
        mcap::MessageStream::new(&bytes).map_err(|e| format!("{shown}: not an MCAP file: {e}"))?;
    let mut order: Vec<String> = Vec::new();
    let mut channels: HashMap<String, Channel> = HashMap::new();
    for (n, message) in stream.enumerate() {
        let m = message.map_err(|e| format!("{shown}: message {}: {e}", n + 1))?;
        let topic = m.channel.topic.clone();
        let ch = channels.entry(topic.clone()).or_insert_with(|| {
            order.push(topic.clone());
            Channel {
                encoding: m.channel.message_encoding.clone(),
                schema: m
                    .channel
                    .schema
                    .as_ref()
                    .map_or_else(String::new, |s| s.name.clone()),
                ..Channel::default()
            }
        });
        ch.log_time.push(m.log_time);
        ch.publish_time.push(m.publish_time);
        ch.sequence.push(u64::from(m.sequence));
        if m.channel.message_encoding == "json" {
            let v: Value = serde_json::from_slice(&m.data)
                .map_err(|e| format!("{shown}: message {} on {topic}: not JSON: {e}", n + 1))?;
            match v {
                Value::Object(o) => ch.flatten("", o),
                v => ch.set("value".into(), Cell::of(v)),
            }
        } else {
            ch.data.push(m.data.into_owned());
        }
        ch.end_row();
    }
    Ok(order
        .into_iter()
        .map(|t| {
            let c = channels.remove(&t).expect("every topic has its channel");
            (t, c)
        })
        .collect())
}

/// `(dtype, shape, bytearray)`: an array of little-endian values.
fn typed<'py>(
    py: Python<'py>,
    dtype: &str,
    shape: &[usize],
    bytes: Vec<u8>,
) -> PyResult<Bound<'py, PyAny>> {
    (
        dtype,
        PyTuple::new(py, shape)?,
        PyByteArray::new(py, &bytes),
    )
        .into_bound_py_any(py)
}

fn floats<'py>(py: Python<'py>, shape: &[usize], v: &[f64]) -> PyResult<Bound<'py, PyAny>> {
    crate::convert::array(py, shape, v)
}

/// A column as a typed array when its cells allow one, else as a list.
fn column<'py>(py: Python<'py>, cells: &[Cell]) -> PyResult<Bound<'py, PyAny>> {
    let n = cells.len();
    let all = |f: fn(&Cell) -> bool| cells.iter().all(f);
    let any_null = cells.iter().any(|c| matches!(c, Cell::Null));
    let numeric = |c: &Cell| {
        matches!(
            c,
            Cell::Int(_) | Cell::UInt(_) | Cell::Float(_) | Cell::Null
        )
    };
    let has_value = cells.iter().any(|c| !matches!(c, Cell::Null));
    if has_value && !any_null && all(|c| matches!(c, Cell::Bool(_))) {
        let bytes = cells
            .iter()
            .map(|c| matches!(c, Cell::Bool(true)) as u8)
            .collect();
        return typed(py, "|b1", &[n], bytes);
    }
    if has_value && !any_null && all(|c| matches!(c, Cell::Int(_))) {
        let bytes = cells
            .iter()
            .flat_map(|c| match c {
                Cell::Int(i) => i.to_le_bytes(),
                _ => unreachable!(),
            })
            .collect();
        return typed(py, "<i8", &[n], bytes);
    }
    let nonnegative_ints =
        |c: &Cell| matches!(c, Cell::UInt(_)) || matches!(c, Cell::Int(i) if *i >= 0);
    if has_value && !any_null && all(nonnegative_ints) {
        let bytes = cells
            .iter()
            .flat_map(|c| match c {
                Cell::UInt(u) => u.to_le_bytes(),
                Cell::Int(i) => (*i as u64).to_le_bytes(),
                _ => unreachable!(),
            })
            .collect();
        return typed(py, "<u8", &[n], bytes);
    }
    if has_value && all(numeric) {
        let v: Vec<f64> = cells
            .iter()
            .map(|c| match c {
                Cell::Int(i) => *i as f64,
                Cell::UInt(u) => *u as f64,
                Cell::Float(f) => *f,
                _ => f64::NAN,
            })
            .collect();
        return floats(py, &[n], &v);
    }
    let width = cells.iter().find_map(|c| match c {
        Cell::Numbers(a) => Some(a.len()),
        _ => None,
    });
    if let Some(w) = width
        && cells
            .iter()
            .all(|c| matches!(c, Cell::Null) || matches!(c, Cell::Numbers(a) if a.len() == w))
    {
        let mut v = Vec::with_capacity(n * w);
        for c in cells {
            match c {
                Cell::Numbers(a) => v.extend(a.iter().map(|x| x.unwrap_or(f64::NAN))),
                _ => v.extend(std::iter::repeat_n(f64::NAN, w)),
            }
        }
        return floats(py, &[n, w], &v);
    }
    let items = cells
        .iter()
        .map(|c| match c {
            Cell::Null => Ok(py.None().into_bound(py)),
            Cell::Bool(b) => b.into_bound_py_any(py),
            Cell::Int(i) => i.into_bound_py_any(py),
            Cell::UInt(u) => u.into_bound_py_any(py),
            Cell::Float(f) => f.into_bound_py_any(py),
            Cell::Str(s) => s.into_bound_py_any(py),
            Cell::Numbers(a) => a.clone().into_bound_py_any(py),
            Cell::Other(v) => json_to_py(py, v),
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)?.into_bound_py_any(py)
}

/// Every channel of the MCAP file `path`, in the order of their first message:
/// `{topic: (info, {column: array or list})}`, `info` holding the message encoding, the schema's
/// name and the number of messages.
#[pyfunction]
pub(crate) fn read_mcap_columns(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let channels = detached(py, move || read(&path).map_err(Failure::Recording))?;
    let out = PyDict::new(py);
    for (topic, ch) in channels {
        let info = PyDict::new(py);
        info.set_item("encoding", &ch.encoding)?;
        info.set_item("schema", &ch.schema)?;
        info.set_item("messages", ch.rows)?;
        let cols = PyDict::new(py);
        let ints = |v: &[u64]| {
            typed(
                py,
                "<u8",
                &[v.len()],
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            )
        };
        cols.set_item("log_time", ints(&ch.log_time)?)?;
        cols.set_item("publish_time", ints(&ch.publish_time)?)?;
        cols.set_item("sequence", ints(&ch.sequence)?)?;
        for (name, cells) in &ch.columns {
            cols.set_item(name, column(py, cells)?)?;
        }
        if !ch.data.is_empty() {
            let data = ch
                .data
                .iter()
                .map(|d| PyBytes::new(py, d))
                .collect::<Vec<_>>();
            cols.set_item("data", PyList::new(py, data)?)?;
        }
        out.set_item(topic, (info, cols))?;
    }
    Ok(out)
}
