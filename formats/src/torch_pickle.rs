//! A safe unpickler for the pickles `torch.save` writes (protocols 2 to 5): it builds a graph of
//! plain values and never calls anything; a global is only a name, and a call (REDUCE, NEWOBJ) is
//! kept as the callable and its arguments for the reader to interpret.

use std::collections::HashMap;

/// Index of an object in [`Pickle::objs`].
pub type Id = usize;

/// One unpickled object. Containers hold ids, so a memoised object shared by several others is
/// one object, mutated in place as Python would, and cycles cost nothing.
#[derive(Debug)]
pub enum Obj {
    None,
    Bool(bool),
    Int(i128),
    /// Floats and bytes hold nothing a state dict's structure needs: only their kind is kept.
    Float,
    Str(String),
    Bytes,
    Tuple(Vec<Id>),
    List(Vec<Id>),
    Dict(Vec<(Id, Id)>),
    Global {
        module: String,
        name: String,
    },
    /// `func(*args)`, never evaluated.
    Call {
        func: Id,
        args: Id,
    },
    /// What the pickler's `persistent_id` returned.
    PersId(Id),
}

/// An unpickled object graph.
#[derive(Debug)]
pub struct Pickle {
    pub objs: Vec<Obj>,
    pub root: Id,
}

impl Pickle {
    pub fn int(&self, id: Id) -> Option<i128> {
        match self.objs[id] {
            Obj::Int(v) => Some(v),
            Obj::Bool(v) => Some(v as i128),
            _ => None,
        }
    }

    pub fn str(&self, id: Id) -> Option<&str> {
        match &self.objs[id] {
            Obj::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The items of a tuple or list.
    pub fn seq(&self, id: Id) -> Option<&[Id]> {
        match &self.objs[id] {
            Obj::Tuple(items) | Obj::List(items) => Some(items),
            _ => None,
        }
    }

    pub fn global(&self, id: Id) -> Option<(&str, &str)> {
        match &self.objs[id] {
            Obj::Global { module, name } => Some((module, name)),
            _ => None,
        }
    }

    /// What an object is, in a few words, for error messages.
    pub fn describe(&self, id: Id) -> String {
        match &self.objs[id] {
            Obj::None => "None".into(),
            Obj::Bool(_) => "a bool".into(),
            Obj::Int(_) => "an int".into(),
            Obj::Float => "a float".into(),
            Obj::Str(_) => "a string".into(),
            Obj::Bytes => "bytes".into(),
            Obj::Tuple(_) => "a tuple".into(),
            Obj::List(_) => "a list".into(),
            Obj::Dict(_) => "a dict".into(),
            Obj::Global { module, name } => format!("the global {module}.{name}"),
            Obj::Call { func, .. } => match self.global(*func) {
                Some((module, name)) => format!("an object built by {module}.{name}"),
                None => "an object built by a call".into(),
            },
            Obj::PersId(_) => "a storage".into(),
        }
    }
}

/// Unpickles one pickle from the start of `data`; returns it and the number of bytes it took.
pub fn load(data: &[u8]) -> Result<(Pickle, usize), String> {
    let mut u =
        Unpickler { data, pos: 0, objs: Vec::new(), stack: Vec::new(), marks: Vec::new(), memo: HashMap::new() };
    let root = u.run()?;
    Ok((Pickle { objs: u.objs, root }, u.pos))
}

struct Unpickler<'a> {
    data: &'a [u8],
    pos: usize,
    objs: Vec<Obj>,
    stack: Vec<Id>,
    marks: Vec<usize>,
    memo: HashMap<u32, Id>,
}

impl Unpickler<'_> {
    fn run(&mut self) -> Result<Id, String> {
        loop {
            let at = self.pos;
            let op = self.take(1)?[0];
            let obj = match op {
                0x80 => {
                    let proto = self.take(1)?[0];
                    if proto > 5 {
                        return Err(format!("pickle protocol {proto} is newer than 5"));
                    }
                    continue;
                }
                0x95 => {
                    self.take(8)?; // FRAME: only a hint for buffered readers
                    continue;
                }
                b'.' => return self.pop(),
                b'(' => {
                    self.marks.push(self.stack.len());
                    continue;
                }
                b'0' => {
                    self.pop()?;
                    continue;
                }
                b'1' => {
                    self.pop_mark()?;
                    continue;
                }
                b'2' => {
                    let top = *self.stack.last().ok_or("DUP on an empty stack")?;
                    self.stack.push(top);
                    continue;
                }
                b'}' => Obj::Dict(Vec::new()),
                b']' => Obj::List(Vec::new()),
                b')' => Obj::Tuple(Vec::new()),
                b't' => Obj::Tuple(self.pop_mark()?),
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    let start = self.stack.len().checked_sub(n).ok_or("TUPLE on too short a stack")?;
                    Obj::Tuple(self.stack.split_off(start))
                }
                b'l' => Obj::List(self.pop_mark()?),
                b'd' => Obj::Dict(pairs(self.pop_mark()?)?),
                b'a' => {
                    let item = self.pop()?;
                    self.extend(vec![item])?;
                    continue;
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    self.extend(items)?;
                    continue;
                }
                b's' => {
                    let value = self.pop()?;
                    let key = self.pop()?;
                    self.set_items(vec![(key, value)])?;
                    continue;
                }
                b'u' => {
                    let items = pairs(self.pop_mark()?)?;
                    self.set_items(items)?;
                    continue;
                }
                b'J' => Obj::Int(i32::from_le_bytes(self.array()?) as i128),
                b'K' => Obj::Int(self.take(1)?[0] as i128),
                b'M' => Obj::Int(u16::from_le_bytes(self.array()?) as i128),
                0x8a => {
                    let n = self.take(1)?[0] as usize;
                    Obj::Int(long(self.take(n)?)?)
                }
                0x8b => {
                    let n = i32::from_le_bytes(self.array()?);
                    Obj::Int(long(self.take(n.try_into().unwrap_or(usize::MAX))?)?)
                }
                b'G' => {
                    self.take(8)?;
                    Obj::Float
                }
                b'N' => Obj::None,
                0x88 => Obj::Bool(true),
                0x89 => Obj::Bool(false),
                b'X' | 0x8c | 0x8d | b'B' | b'C' | 0x8e | b'T' | b'U' => {
                    let n = match op {
                        0x8c | b'C' | b'U' => self.take(1)?[0] as u64,
                        b'X' | b'B' => u32::from_le_bytes(self.array()?) as u64,
                        b'T' => i32::from_le_bytes(self.array()?).try_into().unwrap_or(u64::MAX),
                        _ => u64::from_le_bytes(self.array()?),
                    };
                    let raw = self.take(usize::try_from(n).unwrap_or(usize::MAX))?;
                    match op {
                        b'X' | 0x8c | 0x8d => Obj::Str(
                            std::str::from_utf8(raw)
                                .map_err(|_| format!("string at byte {at} is not UTF-8"))?
                                .to_owned(),
                        ),
                        b'B' | b'C' | 0x8e => Obj::Bytes,
                        // Python 2 strings: read as latin-1 text, as Python 3 does.
                        _ => Obj::Str(raw.iter().map(|&b| b as char).collect()),
                    }
                }
                b'c' => Obj::Global { module: self.line()?, name: self.line()? },
                0x93 => {
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (&self.objs[module], &self.objs[name]) {
                        (Obj::Str(module), Obj::Str(name)) => {
                            Obj::Global { module: module.clone(), name: name.clone() }
                        }
                        _ => return Err(format!("STACK_GLOBAL at byte {at} without two strings")),
                    }
                }
                b'R' | 0x81 => {
                    let args = self.pop()?;
                    let func = self.pop()?;
                    self.call(func, args)
                }
                0x92 => {
                    self.pop()?; // NEWOBJ_EX's keyword arguments
                    let args = self.pop()?;
                    let func = self.pop()?;
                    self.call(func, args)
                }
                // BUILD sets an object's state (an OrderedDict's attributes, say): nothing vkdiff reads.
                b'b' => {
                    self.pop()?;
                    self.stack.last().ok_or("BUILD on an empty stack")?;
                    continue;
                }
                b'q' | b'r' | 0x94 => {
                    let key = match op {
                        b'q' => self.take(1)?[0] as u32,
                        b'r' => u32::from_le_bytes(self.array()?),
                        _ => self.memo.len() as u32,
                    };
                    let top = *self.stack.last().ok_or("memoising from an empty stack")?;
                    self.memo.insert(key, top);
                    continue;
                }
                b'h' | b'j' => {
                    let key = if op == b'h' { self.take(1)?[0] as u32 } else { u32::from_le_bytes(self.array()?) };
                    let id = *self
                        .memo
                        .get(&key)
                        .ok_or_else(|| format!("memo entry {key} read at byte {at} was never written"))?;
                    self.stack.push(id);
                    continue;
                }
                b'Q' => Obj::PersId(self.pop()?),
                b'P' => {
                    let pid = self.line()?;
                    Obj::PersId(self.push_obj(Obj::Str(pid)))
                }
                _ => return Err(format!("unsupported pickle opcode 0x{op:02x} at byte {at}")),
            };
            let id = self.push_obj(obj);
            self.stack.push(id);
        }
    }

    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.data.len()).ok_or("the pickle is truncated")?;
        let bytes = &self.data[self.pos..end];
        self.pos = end;
        Ok(bytes)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        Ok(self.take(N)?.try_into().expect("take returns N bytes"))
    }

    /// A newline-terminated text argument (GLOBAL, PERSID).
    fn line(&mut self) -> Result<String, String> {
        let rest = &self.data[self.pos..];
        let n = rest.iter().position(|&b| b == b'\n').ok_or("the pickle is truncated")?;
        let s = String::from_utf8_lossy(&rest[..n]).into_owned();
        self.pos += n + 1;
        Ok(s)
    }

    fn push_obj(&mut self, obj: Obj) -> Id {
        self.objs.push(obj);
        self.objs.len() - 1
    }

    fn pop(&mut self) -> Result<Id, String> {
        self.stack.pop().ok_or_else(|| "the pickle pops an empty stack".into())
    }

    fn pop_mark(&mut self) -> Result<Vec<Id>, String> {
        let mark = self.marks.pop().ok_or("the pickle uses a MARK it never set")?;
        if mark > self.stack.len() {
            return Err("the pickle's stack shrank below a MARK".into());
        }
        Ok(self.stack.split_off(mark))
    }

    /// `OrderedDict()` is a dict for our purposes; any other call stays opaque.
    fn call(&mut self, func: Id, args: Id) -> Obj {
        let empty_args = matches!(&self.objs[args], Obj::Tuple(a) if a.is_empty());
        if empty_args
            && matches!(&self.objs[func],
                Obj::Global { module, name } if module == "collections" && name == "OrderedDict")
        {
            return Obj::Dict(Vec::new());
        }
        Obj::Call { func, args }
    }

    fn target(&mut self) -> Result<&mut Obj, String> {
        let top = *self.stack.last().ok_or("the pickle adds items to an empty stack")?;
        Ok(&mut self.objs[top])
    }

    fn extend(&mut self, items: Vec<Id>) -> Result<(), String> {
        match self.target()? {
            Obj::List(list) => list.extend(items),
            Obj::Call { .. } => {} // items of an object vkdiff does not read
            other => return Err(format!("APPEND to {}", kind(other))),
        }
        Ok(())
    }

    fn set_items(&mut self, items: Vec<(Id, Id)>) -> Result<(), String> {
        match self.target()? {
            Obj::Dict(dict) => dict.extend(items),
            Obj::Call { .. } => {}
            other => return Err(format!("SETITEM on {}", kind(other))),
        }
        Ok(())
    }
}

fn kind(obj: &Obj) -> &'static str {
    match obj {
        Obj::Tuple(_) => "a tuple",
        Obj::Dict(_) => "a dict",
        Obj::List(_) => "a list",
        _ => "a non-container",
    }
}

fn pairs(items: Vec<Id>) -> Result<Vec<(Id, Id)>, String> {
    if !items.len().is_multiple_of(2) {
        return Err("a dict with a key and no value".into());
    }
    Ok(items.chunks_exact(2).map(|kv| (kv[0], kv[1])).collect())
}

/// A little-endian two's-complement integer (LONG1, LONG4), up to 128 bits.
fn long(bytes: &[u8]) -> Result<i128, String> {
    if bytes.len() > 16 {
        return Err(format!("a {}-byte integer is too large", bytes.len()));
    }
    let fill = if bytes.last().is_some_and(|&b| b & 0x80 != 0) { 0xff } else { 0 };
    let mut wide = [fill; 16];
    wide[..bytes.len()].copy_from_slice(bytes);
    Ok(i128::from_le_bytes(wide))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_protocol_2_dict_with_memo_and_longs() {
        // pickle.dumps({'a': (1, -2, 2**70), 'b': a}, protocol=2) where `a` is the key 'a' itself, so a memo reference
        let p = b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01K\x01J\xfe\xff\xff\xff\
                  \x8a\x09\x00\x00\x00\x00\x00\x00\x00\x00\x40\x87q\x02X\x01\x00\x00\x00bq\x03h\x01u.";
        let (pickle, used) = load(p).unwrap();
        assert_eq!(used, p.len());
        let Obj::Dict(items) = &pickle.objs[pickle.root] else { panic!("not a dict") };
        let values = pickle.seq(items[0].1).unwrap();
        assert_eq!(values.iter().map(|&v| pickle.int(v).unwrap()).collect::<Vec<_>>(), [1, -2, 1 << 70]);
        assert_eq!(pickle.str(items[1].1), Some("a")); // BINGET of memo 1
    }

    #[test]
    fn reads_protocol_4_calls_with_keywords_and_non_ascii_keys() {
        // tools/make_pickle_cases.py: NEWOBJ_EX of __main__.Point, args (3,), kwargs {'y': 4}.
        let p = b"\x80\x04\x95%\x00\x00\x00\x00\x00\x00\x00\x8c\x08__main__\x94\x8c\x05Point\x94\x93\x94K\x03\x85\x94}\
                  \x94\x8c\x01y\x94K\x04s\x92\x94.";
        let (pickle, _) = load(p).unwrap();
        let Obj::Call { func, args } = pickle.objs[pickle.root] else { panic!("not a call") };
        assert_eq!(pickle.global(func), Some(("__main__", "Point")));
        assert_eq!(pickle.seq(args).unwrap().iter().map(|&a| pickle.int(a)).collect::<Vec<_>>(), [Some(3)]);
        // {'gewicht·ä': 1}: SHORT_BINUNICODE is UTF-8, not latin-1.
        let p = b"\x80\x04\x95\x14\x00\x00\x00\x00\x00\x00\x00}\x94\x8c\x0bgewicht\xc2\xb7\xc3\xa4\x94K\x01s.";
        let (pickle, _) = load(p).unwrap();
        let Obj::Dict(items) = &pickle.objs[pickle.root] else { panic!("not a dict") };
        assert_eq!(pickle.str(items[0].0), Some("gewicht·ä"));
    }

    #[test]
    fn refuses_what_it_cannot_read() {
        for (bytes, why) in [
            (&b"\x80\x02}q\x00"[..], "truncated"),
            (b"\x80\x02X\xff\xff\xff\x7fab.", "truncated"),
            (b"\x80\x02h\x05.", "never written"),
            (b"\x80\x02K\x01K\x02a.", "APPEND to a non-container"),
            (b"\x80\x02e.", "MARK it never set"),
            (b"\x80\x02I1\n.", "unsupported pickle opcode 0x49"),
        ] {
            let err = load(bytes).unwrap_err();
            assert!(err.contains(why), "{err}");
        }
    }
}
