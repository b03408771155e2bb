//! NumPy object arrays (`.npy` files whose dtype is `|O`, written with `allow_pickle=True`) read
//! into plain values: the pickled graph of [`super::pickle`] with NumPy's constructors
//! recognised — arrays (`_reconstruct` + `BUILD` state, or protocol 5's `_frombuffer`), their
//! dtypes, and scalars (`multiarray.scalar`). Nothing is executed; any other class is an error.

use std::path::Path;

use super::pickle::{self, Graph, Id, Obj};
use crate::error::{HumanError, Result};

/// Nesting deeper than this is refused (it also stops reference cycles).
const MAX_DEPTH: usize = 64;

/// A Python value of an unpickled object array.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    /// A list or a tuple.
    List(Vec<Value>),
    Dict(Vec<(Value, Value)>),
    Array(NdArray),
}

/// A NumPy array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct NdArray {
    pub shape: Vec<usize>,
    pub data: ArrayData,
}

/// The elements of an [`NdArray`]: numbers (floats, integers and booleans, as `f64`), strings
/// (unicode or bytes dtypes) or Python objects.
#[derive(Clone, Debug, PartialEq)]
pub enum ArrayData {
    Numbers(Vec<f64>),
    Strings(Vec<String>),
    Objects(Vec<Value>),
}

impl Value {
    /// The value under `key` of a dict with string keys.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, Value::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }

    /// The items of a list, or of a 1-D (or 0-D) string or object array, as values.
    pub fn items(&self) -> Option<Vec<Value>> {
        match self {
            Value::List(items) => Some(items.clone()),
            Value::Array(a) => match &a.data {
                ArrayData::Strings(s) => Some(s.iter().cloned().map(Value::Str).collect()),
                ArrayData::Objects(o) => Some(o.clone()),
                ArrayData::Numbers(n) if a.shape.len() <= 1 => {
                    Some(n.iter().map(|&v| Value::Float(v)).collect())
                }
                ArrayData::Numbers(_) => None,
            },
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The numbers of a numeric array, a number, or a (nested) list of numbers, flattened.
    pub fn numbers(&self) -> Option<Vec<f64>> {
        match self {
            Value::Int(i) => Some(vec![*i as f64]),
            Value::Float(f) => Some(vec![*f]),
            Value::Array(NdArray {
                data: ArrayData::Numbers(n),
                ..
            }) => Some(n.clone()),
            Value::List(items) => {
                let parts: Option<Vec<Vec<f64>>> = items.iter().map(Value::numbers).collect();
                Some(parts?.concat())
            }
            _ => None,
        }
    }

    /// What kind of value this is, for error messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool(_) => "a bool",
            Value::Int(_) => "an int",
            Value::Float(_) => "a float",
            Value::Str(_) => "a string",
            Value::Bytes(_) => "bytes",
            Value::List(_) => "a list",
            Value::Dict(_) => "a dict",
            Value::Array(_) => "an array",
        }
    }
}

/// Reads a `.npy` file holding a pickled 0-d object array (what `np.save` writes for a dict)
/// and returns the object inside; any other `.npy` is returned as its array.
pub fn read_object_npy(path: &Path) -> Result<Value> {
    let bytes = std::fs::read(path).map_err(|e| HumanError::io(path, e))?;
    let bad = |m: String| HumanError::format(path, m);
    let npy =
        npyz::NpyFile::new(&bytes[..]).map_err(|e| bad(format!("not a valid .npy file ({e})")))?;
    if !npy.header().uses_pickled_array() {
        return Err(bad(format!(
            "dtype {} is not a pickled object array",
            npy.dtype().descr()
        )));
    }
    let payload: &[u8] = npy.into_inner();
    let graph = pickle::parse(payload).map_err(|e| bad(format!("cannot unpickle: {e}")))?;
    let value = Converter { graph: &graph }
        .value(graph.root, 0)
        .map_err(bad)?;
    Ok(match value {
        Value::Array(NdArray {
            shape,
            data: ArrayData::Objects(mut items),
        }) if shape.is_empty() && items.len() == 1 => items.remove(0),
        other => other,
    })
}

/// Parses an unpickled graph into a value (used by tests with hand-made pickles).
pub fn graph_value(graph: &Graph) -> std::result::Result<Value, String> {
    Converter { graph }.value(graph.root, 0)
}

/// A NumPy dtype: kind character (`f`, `i`, `u`, `b`, `U`, `S`, `O`), bytes per item and byte
/// order.
#[derive(Clone, Copy, Debug)]
struct Dtype {
    kind: char,
    size: usize,
    big_endian: bool,
}

struct Converter<'a> {
    graph: &'a Graph,
}

type R<T> = std::result::Result<T, String>;

impl Converter<'_> {
    fn obj(&self, id: Id) -> &Obj {
        &self.graph.objects[id]
    }

    fn value(&self, id: Id, depth: usize) -> R<Value> {
        if depth > MAX_DEPTH {
            return Err(format!("nested deeper than {MAX_DEPTH} levels"));
        }
        let list = |ids: &[Id]| {
            ids.iter()
                .map(|&i| self.value(i, depth + 1))
                .collect::<R<Vec<_>>>()
        };
        Ok(match self.obj(id) {
            Obj::None => Value::None,
            Obj::Bool(b) => Value::Bool(*b),
            Obj::Int(i) => Value::Int(*i),
            Obj::Float(f) => Value::Float(*f),
            Obj::Str(s) => Value::Str(s.clone()),
            Obj::Bytes(b) => Value::Bytes(b.clone()),
            Obj::LegacyStr(b) => match String::from_utf8(b.clone()) {
                Ok(s) => Value::Str(s),
                Err(_) => Value::Bytes(b.clone()),
            },
            Obj::Tuple(ids) | Obj::List(ids) => Value::List(list(ids)?),
            Obj::Dict(pairs) => Value::Dict(
                pairs
                    .iter()
                    .map(|&(k, v)| Ok((self.value(k, depth + 1)?, self.value(v, depth + 1)?)))
                    .collect::<R<Vec<_>>>()?,
            ),
            Obj::Global { module, name } => {
                return Err(format!("a bare reference to {module}.{name}"));
            }
            Obj::Call { func, args, state } => self.call(*func, *args, *state, depth)?,
        })
    }

    /// The NumPy constructors: arrays, scalars, and `_codecs.encode` (protocol 2's bytes).
    fn call(&self, func: Id, args: Id, state: Option<Id>, depth: usize) -> R<Value> {
        let (module, name) = self.global(func)?;
        match name {
            "_reconstruct" if module.ends_with("multiarray") => {
                let state = state.ok_or("an ndarray without its state")?;
                self.reconstruct(state, depth)
            }
            "_frombuffer" => self.frombuffer(args),
            "scalar" if module.ends_with("multiarray") => self.scalar(args),
            "encode" if module == "_codecs" => Ok(Value::Bytes(self.encoded(args)?)),
            _ => Err(format!("objects of {module}.{name} are not supported")),
        }
    }

    fn global(&self, id: Id) -> R<(&str, &str)> {
        match self.obj(id) {
            Obj::Global { module, name } => Ok((module, name)),
            _ => Err("a call of something that is not a module attribute".into()),
        }
    }

    fn tuple(&self, id: Id) -> R<&[Id]> {
        match self.obj(id) {
            Obj::Tuple(items) => Ok(items),
            _ => Err("expected a tuple".into()),
        }
    }

    fn int(&self, id: Id) -> R<i64> {
        match self.obj(id) {
            Obj::Int(i) => Ok(*i),
            _ => Err("expected an integer".into()),
        }
    }

    fn text(&self, id: Id) -> R<String> {
        match self.obj(id) {
            Obj::Str(s) => Ok(s.clone()),
            Obj::LegacyStr(b) => Ok(String::from_utf8_lossy(b).into_owned()),
            _ => Err("expected a string".into()),
        }
    }

    /// Raw bytes: `bytes`, a Python 2 `str`, a latin-1 `str`, or `_codecs.encode(s, 'latin1')`
    /// (how protocol 2 stores bytes).
    fn bytes(&self, id: Id) -> R<Vec<u8>> {
        match self.obj(id) {
            Obj::Call { func, args, .. } if self.global(*func)? == ("_codecs", "encode") => {
                self.encoded(*args)
            }
            _ => self.raw(id),
        }
    }

    fn raw(&self, id: Id) -> R<Vec<u8>> {
        match self.obj(id) {
            Obj::Bytes(b) | Obj::LegacyStr(b) => Ok(b.clone()),
            Obj::Str(s) => s
                .chars()
                .map(|c| {
                    u8::try_from(c as u32).map_err(|_| "a non-latin-1 byte string".to_string())
                })
                .collect(),
            _ => Err("expected bytes".into()),
        }
    }

    /// The bytes of `_codecs.encode(text, 'latin1')` from its argument tuple.
    fn encoded(&self, args: Id) -> R<Vec<u8>> {
        self.raw(
            *self
                .tuple(args)?
                .first()
                .ok_or("encode() without a string")?,
        )
    }

    fn shape(&self, id: Id) -> R<Vec<usize>> {
        let dims = match self.obj(id) {
            Obj::Int(n) => vec![*n],
            _ => self
                .tuple(id)?
                .iter()
                .map(|&d| self.int(d))
                .collect::<R<Vec<_>>>()?,
        };
        dims.into_iter()
            .map(|d| usize::try_from(d).map_err(|_| format!("negative dimension {d}")))
            .collect()
    }

    /// A `numpy.dtype(name, align, copy)` call with its `BUILD` state.
    fn dtype(&self, id: Id) -> R<Dtype> {
        let Obj::Call { func, args, state } = self.obj(id) else {
            return Err("expected a dtype".into());
        };
        if self.global(*func)?.1 != "dtype" {
            return Err("expected a dtype".into());
        }
        let name = self.text(*self.tuple(*args)?.first().ok_or("dtype without a name")?)?;
        let order = match state {
            Some(s) => self.tuple(*s)?.get(1).map(|&o| self.text(o)).transpose()?,
            None => None,
        };
        let mut chars = name.chars();
        let kind = chars.next().ok_or("empty dtype name")?;
        let count: usize = chars
            .as_str()
            .parse()
            .map_err(|_| format!("dtype {name:?}"))?;
        let size = if kind == 'U' { count * 4 } else { count };
        Ok(Dtype {
            kind,
            size,
            big_endian: order.as_deref() == Some(">"),
        })
    }

    /// An ndarray's `BUILD` state `(version, shape, dtype, is_fortran, data)`.
    fn reconstruct(&self, state: Id, depth: usize) -> R<Value> {
        let s = self.tuple(state)?;
        if s.len() != 5 {
            return Err(format!("ndarray state of {} items (expected 5)", s.len()));
        }
        let shape = self.shape(s[1])?;
        let dtype = self.dtype(s[2])?;
        let fortran = matches!(self.obj(s[3]), Obj::Bool(true));
        let data = if dtype.kind == 'O' {
            let Obj::List(items) = self.obj(s[4]) else {
                return Err("object array without a list of items".into());
            };
            let items = items
                .iter()
                .map(|&i| self.value(i, depth + 1))
                .collect::<R<Vec<_>>>()?;
            ArrayData::Objects(items)
        } else {
            decode(&self.bytes(s[4])?, dtype)?
        };
        array(shape, data, fortran)
    }

    /// Protocol 5's `_frombuffer(buffer, dtype, shape, order)`.
    fn frombuffer(&self, args: Id) -> R<Value> {
        let a = self.tuple(args)?;
        if a.len() != 4 {
            return Err("_frombuffer needs 4 arguments".into());
        }
        let dtype = self.dtype(a[1])?;
        let data = decode(&self.bytes(a[0])?, dtype)?;
        array(self.shape(a[2])?, data, self.text(a[3])? == "F")
    }

    /// `multiarray.scalar(dtype, bytes)`: a NumPy scalar.
    fn scalar(&self, args: Id) -> R<Value> {
        let a = self.tuple(args)?;
        let dtype = self.dtype(*a.first().ok_or("scalar without a dtype")?)?;
        let bytes = self.bytes(*a.get(1).ok_or("scalar without data")?)?;
        match decode(&bytes, dtype)? {
            ArrayData::Numbers(n) if n.len() == 1 => Ok(match dtype.kind {
                'f' => Value::Float(n[0]),
                'b' => Value::Bool(n[0] != 0.0),
                _ => Value::Int(n[0] as i64),
            }),
            ArrayData::Strings(s) if s.len() == 1 => Ok(Value::Str(s[0].clone())),
            _ => Err("a scalar of unexpected size".into()),
        }
    }
}

/// An array value after checking the element count, reordering Fortran data to C order.
fn array(shape: Vec<usize>, data: ArrayData, fortran: bool) -> R<Value> {
    let len = match &data {
        ArrayData::Numbers(v) => v.len(),
        ArrayData::Strings(v) => v.len(),
        ArrayData::Objects(v) => v.len(),
    };
    let count = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    if count != Some(len) {
        return Err(format!("shape {shape:?} but {len} elements"));
    }
    let data = match data {
        ArrayData::Numbers(v) if fortran => ArrayData::Numbers(fortran_to_c(&v, &shape)),
        other => other,
    };
    Ok(Value::Array(NdArray { shape, data }))
}

/// Decodes raw array bytes of `dtype`.
fn decode(bytes: &[u8], dtype: Dtype) -> R<ArrayData> {
    let size = dtype.size;
    if size == 0 || !bytes.len().is_multiple_of(size) {
        return Err(format!(
            "{} bytes of {}{size}-byte items",
            bytes.len(),
            dtype.kind
        ));
    }
    let items = bytes.chunks_exact(size);
    let number = |c: &[u8]| -> R<f64> {
        let mut b = c.to_vec();
        if dtype.big_endian {
            b.reverse();
        }
        let mut w = [0u8; 8];
        w[..size.min(8)].copy_from_slice(&b[..size.min(8)]);
        let signed = |bits: u32| (i64::from_le_bytes(w) << (64 - bits)) >> (64 - bits);
        Ok(match (dtype.kind, size) {
            ('f', 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            ('f', 8) => f64::from_le_bytes(w),
            ('i', 1 | 2 | 4 | 8) => signed(size as u32 * 8) as f64,
            ('u' | 'b', 1 | 2 | 4 | 8) => u64::from_le_bytes(w) as f64,
            (k, s) => return Err(format!("dtype {k}{s} is not supported")),
        })
    };
    Ok(match dtype.kind {
        'U' => ArrayData::Strings(
            items
                .map(|c| utf32(c, dtype.big_endian))
                .collect::<R<_>>()?,
        ),
        'S' => ArrayData::Strings(
            items
                .map(|c| String::from_utf8_lossy(trim_nul(c)).into_owned())
                .collect(),
        ),
        _ => ArrayData::Numbers(items.map(number).collect::<R<_>>()?),
    })
}

fn trim_nul(b: &[u8]) -> &[u8] {
    let end = b.iter().rposition(|&c| c != 0).map_or(0, |i| i + 1);
    &b[..end]
}

/// A NumPy unicode item: UTF-32 code units, padded with NULs.
fn utf32(c: &[u8], big_endian: bool) -> R<String> {
    c.chunks_exact(4)
        .map(|u| {
            let b = [u[0], u[1], u[2], u[3]];
            if big_endian {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            }
        })
        .take_while(|&u| u != 0)
        .map(|u| char::from_u32(u).ok_or_else(|| format!("invalid code point {u:#x}")))
        .collect()
}

/// Reorders a Fortran-order buffer (first index fastest) into C order.
fn fortran_to_c(data: &[f64], shape: &[usize]) -> Vec<f64> {
    let mut out = Vec::with_capacity(data.len());
    let mut index = vec![0usize; shape.len()];
    for _ in 0..data.len() {
        let mut offset = 0;
        let mut stride = 1;
        for (k, &i) in index.iter().enumerate() {
            offset += i * stride;
            stride *= shape[k];
        }
        out.push(data[offset]);
        for k in (0..shape.len()).rev() {
            index[k] += 1;
            if index[k] < shape[k] {
                break;
            }
            index[k] = 0;
        }
    }
    out
}
