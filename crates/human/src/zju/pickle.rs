//! A reader for the part of Python's pickle format that NumPy writes for object arrays
//! (`np.save(path, obj, allow_pickle=True)`, as ZJU-MoCap's `annots.npy` and SMPL `params/*.npy`
//! are stored): binary protocols 2 to 5 with lists, tuples, dicts, strings, bytes, numbers and
//! calls to module globals.
//!
//! Unpickling runs a small stack machine whose result is an object graph ([`Graph`]): calls
//! (`REDUCE`, `NEWOBJ`) are *recorded*, never executed, with the state `BUILD` gives them, so
//! reading an untrusted file runs no code. [`super::numpy`] turns the graph into values,
//! recognising NumPy's array and scalar constructors. The stack machine follows the opcode
//! semantics of CPython's `pickletools` documentation; text-mode (protocol 0/1) opcodes other
//! than `GLOBAL`, `PUT` and `GET` are not supported, since NumPy never writes them.

use std::collections::HashMap;

/// Index of an object in [`Graph::objects`].
pub type Id = usize;

/// One object of an unpickled graph. Lists and dicts are referenced by [`Id`] so that the memo
/// can share them, as Python does.
#[derive(Clone, Debug, PartialEq)]
pub enum Obj {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    /// A Python 2 `str` (`BINSTRING`): bytes that are often text.
    LegacyStr(Vec<u8>),
    Tuple(Vec<Id>),
    List(Vec<Id>),
    Dict(Vec<(Id, Id)>),
    /// A module attribute (`numpy.dtype`, `numpy._core.multiarray._reconstruct`).
    Global {
        module: String,
        name: String,
    },
    /// `func(*args)`, recorded and not run, with the state `BUILD` set on it.
    Call {
        func: Id,
        args: Id,
        state: Option<Id>,
    },
}

/// The objects of one pickle and the one it returns.
#[derive(Clone, Debug)]
pub struct Graph {
    pub objects: Vec<Obj>,
    pub root: Id,
}

enum Item {
    Mark,
    Obj(Id),
}

struct Machine<'a> {
    input: &'a [u8],
    pos: usize,
    objects: Vec<Obj>,
    stack: Vec<Item>,
    memo: HashMap<u64, Id>,
}

/// Unpickles `bytes` into an object graph; the error says what is wrong and at which byte.
pub fn parse(bytes: &[u8]) -> Result<Graph, String> {
    let mut m = Machine {
        input: bytes,
        pos: 0,
        objects: Vec::new(),
        stack: Vec::new(),
        memo: HashMap::new(),
    };
    loop {
        let at = m.pos;
        let op = m.byte()?;
        if op == b'.' {
            let root = m.pop().map_err(|e| format!("{e} at STOP"))?;
            return Ok(Graph {
                objects: m.objects,
                root,
            });
        }
        m.step(op)
            .map_err(|e| format!("pickle byte {at} (opcode 0x{op:02x}): {e}"))?;
    }
}

impl Machine<'_> {
    fn step(&mut self, op: u8) -> Result<(), String> {
        match op {
            0x80 => {
                let proto = self.byte()?;
                if proto > 5 {
                    return Err(format!("pickle protocol {proto} is newer than 5"));
                }
            }
            0x95 => {
                self.take(8)?;
            }
            b'(' => self.stack.push(Item::Mark),
            b'0' => {
                self.stack.pop().ok_or("POP on an empty stack")?;
            }
            b'1' => drop(self.pop_mark()?),
            b'2' => {
                let top = self.top()?;
                self.stack.push(Item::Obj(top));
            }
            _ => return self.step_value(op),
        }
        Ok(())
    }

    /// Opcodes that push a scalar, a string or a container.
    fn step_value(&mut self, op: u8) -> Result<(), String> {
        let obj = match op {
            b'N' => Obj::None,
            0x88 => Obj::Bool(true),
            0x89 => Obj::Bool(false),
            b'J' => Obj::Int(i32::from_le_bytes(self.array()?) as i64),
            b'K' => Obj::Int(self.byte()? as i64),
            b'M' => Obj::Int(u16::from_le_bytes(self.array()?) as i64),
            0x8a => {
                let n = self.byte()? as usize;
                Obj::Int(long(self.take(n)?)?)
            }
            0x8b => {
                let n = self.length(4)?;
                Obj::Int(long(self.take(n)?)?)
            }
            b'G' => Obj::Float(f64::from_be_bytes(self.array()?)),
            b'U' | b'T' => {
                let n = if op == b'U' {
                    self.byte()? as usize
                } else {
                    self.length(4)?
                };
                Obj::LegacyStr(self.take(n)?.to_vec())
            }
            b'X' | 0x8c | 0x8d => {
                let n = match op {
                    0x8c => self.byte()? as usize,
                    b'X' => self.length(4)?,
                    _ => self.length(8)?,
                };
                let text =
                    std::str::from_utf8(self.take(n)?).map_err(|_| "invalid UTF-8 string")?;
                Obj::Str(text.to_owned())
            }
            b'C' | b'B' | 0x8e | 0x96 => {
                let n = match op {
                    b'C' => self.byte()? as usize,
                    b'B' => self.length(4)?,
                    _ => self.length(8)?,
                };
                Obj::Bytes(self.take(n)?.to_vec())
            }
            _ => return self.step_container(op),
        };
        self.push(obj);
        Ok(())
    }

    /// Opcodes that build or fill tuples, lists and dicts.
    fn step_container(&mut self, op: u8) -> Result<(), String> {
        match op {
            b')' => self.push(Obj::Tuple(Vec::new())),
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                let mut items = (0..n).map(|_| self.pop()).collect::<Result<Vec<_>, _>>()?;
                items.reverse();
                self.push(Obj::Tuple(items));
            }
            b't' => {
                let items = self.pop_mark()?;
                self.push(Obj::Tuple(items));
            }
            b']' => self.push(Obj::List(Vec::new())),
            b'l' => {
                let items = self.pop_mark()?;
                self.push(Obj::List(items));
            }
            b'a' | b'e' => {
                let items = if op == b'a' {
                    vec![self.pop()?]
                } else {
                    self.pop_mark()?
                };
                let top = self.top()?;
                match &mut self.objects[top] {
                    Obj::List(list) => list.extend(items),
                    _ => return Err("APPEND to something that is not a list".into()),
                }
            }
            b'}' => self.push(Obj::Dict(Vec::new())),
            b'd' => {
                let items = self.pop_mark()?;
                self.push(Obj::Dict(pairs(items)?));
            }
            b's' | b'u' => {
                let items = if op == b's' {
                    let v = self.pop()?;
                    vec![self.pop()?, v]
                } else {
                    self.pop_mark()?
                };
                let new = pairs(items)?;
                let top = self.top()?;
                match &mut self.objects[top] {
                    Obj::Dict(dict) => dict.extend(new),
                    _ => return Err("SETITEM on something that is not a dict".into()),
                }
            }
            _ => return self.step_object(op),
        }
        Ok(())
    }

    /// Globals, calls, `BUILD` and the memo.
    fn step_object(&mut self, op: u8) -> Result<(), String> {
        match op {
            b'c' => {
                let module = self.line()?;
                let name = self.line()?;
                self.push(Obj::Global { module, name });
            }
            0x93 => {
                let name = self.pop_str()?;
                let module = self.pop_str()?;
                self.push(Obj::Global { module, name });
            }
            b'R' | 0x81 => {
                let args = self.pop()?;
                let func = self.pop()?;
                self.push(Obj::Call {
                    func,
                    args,
                    state: None,
                });
            }
            b'b' => {
                let new_state = self.pop()?;
                let top = self.top()?;
                match &mut self.objects[top] {
                    Obj::Call { state, .. } => *state = Some(new_state),
                    _ => return Err("BUILD on something that is not an object".into()),
                }
            }
            b'q' | b'r' | 0x94 | b'p' => {
                let key = match op {
                    b'q' => self.byte()? as u64,
                    b'r' => u32::from_le_bytes(self.array()?) as u64,
                    b'p' => self.line()?.parse().map_err(|_| "bad PUT index")?,
                    _ => self.memo.len() as u64,
                };
                let top = self.top()?;
                self.memo.insert(key, top);
            }
            b'h' | b'j' | b'g' => {
                let key = match op {
                    b'h' => self.byte()? as u64,
                    b'j' => u32::from_le_bytes(self.array()?) as u64,
                    _ => self.line()?.parse().map_err(|_| "bad GET index")?,
                };
                let id = *self
                    .memo
                    .get(&key)
                    .ok_or(format!("memo entry {key} was never stored"))?;
                self.stack.push(Item::Obj(id));
            }
            _ => return Err("unsupported opcode".into()),
        }
        Ok(())
    }

    fn push(&mut self, obj: Obj) {
        self.objects.push(obj);
        self.stack.push(Item::Obj(self.objects.len() - 1));
    }

    fn pop(&mut self) -> Result<Id, String> {
        match self.stack.pop() {
            Some(Item::Obj(id)) => Ok(id),
            Some(Item::Mark) => Err("found a MARK where a value was expected".into()),
            None => Err("stack is empty".into()),
        }
    }

    fn top(&self) -> Result<Id, String> {
        match self.stack.last() {
            Some(Item::Obj(id)) => Ok(*id),
            _ => Err("no value on the stack".into()),
        }
    }

    fn pop_mark(&mut self) -> Result<Vec<Id>, String> {
        let mut items = Vec::new();
        loop {
            match self.stack.pop() {
                Some(Item::Obj(id)) => items.push(id),
                Some(Item::Mark) => break,
                None => return Err("no MARK on the stack".into()),
            }
        }
        items.reverse();
        Ok(items)
    }

    fn pop_str(&mut self) -> Result<String, String> {
        let id = self.pop()?;
        match &self.objects[id] {
            Obj::Str(s) => Ok(s.clone()),
            Obj::LegacyStr(b) => Ok(String::from_utf8_lossy(b).into_owned()),
            _ => Err("STACK_GLOBAL needs two strings".into()),
        }
    }

    fn byte(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut out = [0; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    /// A little-endian length of `width` bytes (4 or 8).
    fn length(&mut self, width: usize) -> Result<usize, String> {
        let mut buf = [0u8; 8];
        buf[..width].copy_from_slice(self.take(width)?);
        usize::try_from(u64::from_le_bytes(buf)).map_err(|_| "length too large".into())
    }

    /// The next `n` bytes; an error (not an allocation) when fewer remain.
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.input.len());
        let end = end.ok_or_else(|| format!("truncated: {n} bytes needed at byte {}", self.pos))?;
        let out = &self.input[self.pos..end];
        self.pos = end;
        Ok(out)
    }

    fn line(&mut self) -> Result<String, String> {
        let rest = &self.input[self.pos..];
        let n = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or("unterminated line")?;
        let text = String::from_utf8_lossy(&rest[..n]).into_owned();
        self.pos += n + 1;
        Ok(text)
    }
}

/// A little-endian two's-complement integer of at most 8 bytes.
fn long(bytes: &[u8]) -> Result<i64, String> {
    if bytes.len() > 8 {
        return Err(format!(
            "integer of {} bytes does not fit 64 bits",
            bytes.len()
        ));
    }
    let fill = if bytes.last().is_some_and(|&b| b & 0x80 != 0) {
        0xff
    } else {
        0
    };
    let mut buf = [fill; 8];
    buf[..bytes.len()].copy_from_slice(bytes);
    Ok(i64::from_le_bytes(buf))
}

fn pairs(items: Vec<Id>) -> Result<Vec<(Id, Id)>, String> {
    if !items.len().is_multiple_of(2) {
        return Err("odd number of items for a dict".into());
    }
    Ok(items.chunks_exact(2).map(|p| (p[0], p[1])).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python2_dict_with_legacy_strings_and_memo() {
        // Python 2's pickle.dumps({'K': [3, -2], 'a': 0.5}, 2), written out by hand.
        let bytes = b"\x80\x02}q\x00(U\x01Kq\x01]q\x02(K\x03J\xfe\xff\xff\xffeU\x01aG?\xe0\x00\x00\x00\x00\x00\x00u.";
        let g = parse(bytes).unwrap();
        let Obj::Dict(items) = &g.objects[g.root] else {
            panic!("not a dict")
        };
        assert_eq!(items.len(), 2);
        assert_eq!(g.objects[items[0].0], Obj::LegacyStr(b"K".to_vec()));
        let Obj::List(list) = &g.objects[items[0].1] else {
            panic!("not a list")
        };
        assert_eq!(g.objects[list[1]], Obj::Int(-2));
        assert_eq!(g.objects[items[1].1], Obj::Float(0.5));
    }

    #[test]
    fn long_integers_are_twos_complement() {
        assert_eq!(long(&[0xff]).unwrap(), -1);
        assert_eq!(long(&[0x00, 0x01]).unwrap(), 256);
        assert_eq!(long(&[]).unwrap(), 0);
        assert!(long(&[0; 9]).is_err());
    }

    #[test]
    fn truncated_and_malformed_input_are_errors_not_panics() {
        for bad in [
            &b"\x80\x02"[..],
            b"\x80\x02X\xff\xff\xff\x7f",
            b"\x80\x02a.",
            b"\x80\x02h\x05.",
            b"\x80\x02(.",
            b"\x80\x09N.",
            b"\x80\x02K\x01K\x02s.",
            b"\x80\x02\xff",
        ] {
            assert!(parse(bad).is_err(), "{bad:?}");
        }
    }
}
