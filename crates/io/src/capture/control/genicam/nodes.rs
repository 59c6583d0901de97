//! The GenICam node map subset: features read and written through a camera's registers.
//!
//! In: the root of a GenICam XML file ([`super::xml`]) and a [`Port`] onto the camera's
//! registers. Out: feature values by name ([`NodeMap::get`], [`NodeMap::set`], enumerations by
//! entry name), ranges ([`NodeMap::range`]), or a [`NodeError`] naming the node at fault.
//!
//! Node kinds understood: `Integer`, `Float`, `Boolean`, `Enumeration` (with `EnumEntry`),
//! `IntReg`, `MaskedIntReg`, `FloatReg`, `StructReg`/`StructEntry`, `Converter`, `IntConverter`,
//! `SwissKnife` and `IntSwissKnife` ([`super::formula`]); on them `Value`/`pValue`,
//! `Min`/`pMin`, `Max`/`pMax`, `Inc`/`pInc`, `OnValue`/`OffValue`, `Address` and `pAddress`
//! (summed), `Length`, `Endianess`, `Sign`, `LSB`/`MSB`/`Bit`, `AccessMode`,
//! `ImposedAccessMode`, `pIsImplemented`, `pIsAvailable`, `pIsLocked`, `pVariable`,
//! `Constant`, `FormulaTo`/`FormulaFrom`/`Formula`, and selector-indexed registers (`pIndex`
//! with `Offset` or `pOffset`). Not understood, each an error naming the node: any other kind
//! (`Command`, `String`, `StringReg`, `Register`, SwissKnives with `Expression`s, …), variables
//! with a suffix (`X.Max`), ports other than the device's. No value is cached: every read goes to the camera.

use super::formula;
use super::xml::Element;
use std::collections::HashMap;
use std::fmt;

/// Deepest chain of node references followed (a cycle in a broken file ends here).
const MAX_DEPTH: usize = 32;

/// The camera's registers.
pub trait Port {
    fn read(&mut self, address: u64, len: usize) -> Result<Vec<u8>, String>;
    fn write(&mut self, address: u64, data: &[u8]) -> Result<(), String>;
}

/// A feature that cannot be read or written: the node at fault and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeError {
    pub node: String,
    pub kind: NodeErrorKind,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NodeErrorKind {
    /// No node of that name (or not implemented, by its `pIsImplemented`).
    Missing,
    /// A node kind or element this subset does not read.
    Unsupported(String),
    /// Read-only, locked, not available now, or a constant.
    NotWritable(String),
    /// The register access failed (the port's message).
    Port(String),
    /// The file says something impossible (a bad number, a register of 3 bytes as a float).
    Invalid(String),
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = &self.node;
        match &self.kind {
            NodeErrorKind::Missing => write!(f, "the camera's GenICam file has no feature '{n}'"),
            NodeErrorKind::Unsupported(what) => {
                write!(f, "'{n}': {what} is not supported by omnitrack's GenICam reader")
            }
            NodeErrorKind::NotWritable(why) => write!(f, "'{n}' is {why}"),
            NodeErrorKind::Port(why) => write!(f, "'{n}': {why}"),
            NodeErrorKind::Invalid(why) => write!(f, "'{n}': {why}"),
        }
    }
}

fn error(node: &str, kind: NodeErrorKind) -> NodeError {
    NodeError {
        node: node.to_string(),
        kind,
    }
}

/// The nodes of one GenICam file, by name.
pub struct NodeMap {
    nodes: HashMap<String, Element>,
}

fn number(text: &str) -> Option<f64> {
    let t = text.trim();
    if let Some(hex) = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        return u64::from_str_radix(hex, 16).ok().map(|v| v as f64);
    }
    t.parse::<f64>().ok()
}

impl NodeMap {
    /// Indexes every named node of the file (inside `Group`s too; `StructEntry`s become
    /// `MaskedIntReg`s with their `StructReg`'s register).
    pub fn new(root: &Element) -> NodeMap {
        let mut nodes = HashMap::new();
        fn walk(e: &Element, nodes: &mut HashMap<String, Element>) {
            for c in &e.children {
                if c.name == "Group" {
                    walk(c, nodes);
                } else if c.name == "StructReg" {
                    for entry in c.children_named("StructEntry") {
                        let Some(name) = entry.attribute("Name") else { continue };
                        let mut node = entry.clone();
                        node.name = "MaskedIntReg".into();
                        let inherited = c
                            .children
                            .iter()
                            .filter(|p| p.name != "StructEntry" && node.child(&p.name).is_none())
                            .cloned();
                        node.children.extend(inherited.collect::<Vec<_>>());
                        nodes.insert(name.to_string(), node);
                    }
                } else if let Some(name) = c.attribute("Name") {
                    nodes.insert(name.to_string(), c.clone());
                }
            }
        }
        walk(root, &mut nodes);
        NodeMap { nodes }
    }

    /// The node's kind (`Float`, `IntReg`, …), if the file has it.
    pub fn kind(&self, name: &str) -> Option<&str> {
        self.nodes.get(name).map(|e| e.name.as_str())
    }

    /// Whether the feature exists and is implemented (`pIsImplemented`, where readable).
    pub fn has(&self, port: &mut dyn Port, name: &str) -> bool {
        match self.nodes.get(name) {
            None => false,
            Some(e) => match e.child_text("pIsImplemented") {
                Some(p) => self.get_at(port, p, 0).map(|v| v != 0.0).unwrap_or(true),
                None => true,
            },
        }
    }

    fn node(&self, name: &str) -> Result<&Element, NodeError> {
        self.nodes.get(name).ok_or_else(|| error(name, NodeErrorKind::Missing))
    }

    /// A feature's value (an enumeration's as its integer).
    pub fn get(&self, port: &mut dyn Port, name: &str) -> Result<f64, NodeError> {
        self.get_at(port, name, 0)
    }

    /// A value written as `<X>` or `<pX>` under `e`, if either is there.
    fn value_of(&self, port: &mut dyn Port, e: &Element, key: &str, depth: usize) -> Result<Option<f64>, NodeError> {
        if let Some(p) = e.child_text(&format!("p{key}")) {
            return self.get_at(port, p, depth + 1).map(Some);
        }
        match e.child_text(key) {
            None => Ok(None),
            Some(t) => number(t).map(Some).ok_or_else(|| {
                error(
                    e.attribute("Name").unwrap_or(key),
                    NodeErrorKind::Invalid(format!("<{key}> '{t}' is not a number")),
                )
            }),
        }
    }

    fn get_at(&self, port: &mut dyn Port, name: &str, depth: usize) -> Result<f64, NodeError> {
        if depth > MAX_DEPTH {
            return Err(error(
                name,
                NodeErrorKind::Invalid("node references nested too deeply (a cycle?)".into()),
            ));
        }
        let e = self.node(name)?;
        match e.name.as_str() {
            "Integer" | "Float" | "Boolean" | "Enumeration" => self
                .value_of(port, e, "Value", depth)?
                .ok_or_else(|| error(name, NodeErrorKind::Invalid("neither <Value> nor <pValue>".into()))),
            "IntReg" | "MaskedIntReg" | "FloatReg" => {
                let (address, len) = self.register(port, e, name, depth)?;
                let bytes = port
                    .read(address, len)
                    .map_err(|m| error(name, NodeErrorKind::Port(m)))?;
                decode(e, name, &bytes)
            }
            "Converter" | "IntConverter" => {
                let from = self.get_at(port, child(e, name, "pValue")?, depth + 1)?;
                let v = self.formula(port, e, name, "FormulaFrom", Some(("FROM", from)), depth)?;
                Ok(if e.name == "IntConverter" { v.round() } else { v })
            }
            "SwissKnife" | "IntSwissKnife" => {
                let v = self.formula(port, e, name, "Formula", None, depth)?;
                Ok(if e.name == "IntSwissKnife" { v.trunc() } else { v })
            }
            other => Err(error(name, NodeErrorKind::Unsupported(format!("node kind '{other}'")))),
        }
    }

    fn formula(
        &self,
        port: &mut dyn Port,
        e: &Element,
        name: &str,
        which: &str,
        extra: Option<(&str, f64)>,
        depth: usize,
    ) -> Result<f64, NodeError> {
        if e.child("Expression").is_some() {
            return Err(error(name, NodeErrorKind::Unsupported("<Expression>".into())));
        }
        let text = child(e, name, which)?;
        let wanted = formula::variables(text)
            .map_err(|m| error(name, NodeErrorKind::Unsupported(format!("{which} '{text}': {m}"))))?;
        let mut vars: Vec<(String, f64)> = Vec::new();
        for var in wanted {
            if vars.iter().any(|(n, _)| *n == var) || extra.is_some_and(|(n, _)| n == var) {
                continue;
            }
            let node = e
                .children_named("pVariable")
                .find(|v| v.attribute("Name") == Some(var.as_str()))
                .map(|v| v.text.clone());
            let value = match node {
                Some(n) => self.get_at(port, &n, depth + 1)?,
                None => match e
                    .children_named("Constant")
                    .find(|v| v.attribute("Name") == Some(var.as_str()))
                {
                    Some(c) => number(&c.text).ok_or_else(|| {
                        error(name, NodeErrorKind::Invalid(format!("constant {var} is not a number")))
                    })?,
                    None if var.contains('.') => {
                        return Err(error(
                            name,
                            NodeErrorKind::Unsupported(format!("the variable suffix of '{var}'")),
                        ))
                    }
                    None => {
                        return Err(error(
                            name,
                            NodeErrorKind::Invalid(format!("{which} uses '{var}', which no pVariable names")),
                        ))
                    }
                },
            };
            vars.push((var, value));
        }
        let lookup = |n: &str| {
            extra
                .filter(|(k, _)| *k == n)
                .map(|(_, v)| v)
                .or_else(|| vars.iter().find(|(k, _)| k == n).map(|(_, v)| *v))
        };
        formula::evaluate(text, &lookup)
            .map_err(|m| error(name, NodeErrorKind::Unsupported(format!("{which} '{text}': {m}"))))
    }

    /// A register node's address (every `Address` and `pAddress` summed) and length.
    fn register(&self, port: &mut dyn Port, e: &Element, name: &str, depth: usize) -> Result<(u64, usize), NodeError> {
        // A selector-indexed register: the selector's value times the offset, added.
        let mut indexed = 0f64;
        if let Some(index) = e.child("pIndex") {
            let offset = match (index.attribute("Offset"), index.attribute("pOffset")) {
                (Some(o), _) => {
                    number(o).ok_or_else(|| error(name, NodeErrorKind::Invalid(format!("bad pIndex Offset '{o}'"))))?
                }
                (None, Some(p)) => self.get_at(port, p, depth + 1)?,
                (None, None) => 1.0,
            };
            indexed = self.get_at(port, &index.text, depth + 1)? * offset;
        }
        if let Some(p) = e.child_text("pPort").filter(|p| *p != "Device") {
            return Err(error(name, NodeErrorKind::Unsupported(format!("the port '{p}'"))));
        }
        let mut address = 0f64;
        let mut any = false;
        for a in e.children_named("Address") {
            address += number(&a.text)
                .ok_or_else(|| error(name, NodeErrorKind::Invalid(format!("bad <Address> '{}'", a.text))))?;
            any = true;
        }
        for p in e.children_named("pAddress") {
            address += self.get_at(port, &p.text, depth + 1)?;
            any = true;
        }
        let len = match e.child_text("Length").and_then(number) {
            Some(l) if (1.0..=8.0).contains(&l) && l.fract() == 0.0 => l as usize,
            _ => {
                return Err(error(
                    name,
                    NodeErrorKind::Invalid("<Length> must be 1 to 8 bytes".into()),
                ))
            }
        };
        address += indexed;
        if !any || address < 0.0 || !address.is_finite() {
            return Err(error(name, NodeErrorKind::Invalid("no register address".into())));
        }
        Ok((address as u64, len))
    }

    /// Whether the node can be written now: not read-only by its access mode, available and
    /// not locked (where those can be read).
    fn writable(&self, port: &mut dyn Port, e: &Element, name: &str, depth: usize) -> Result<(), NodeError> {
        for key in ["AccessMode", "ImposedAccessMode"] {
            if e.child_text(key) == Some("RO") {
                return Err(error(name, NodeErrorKind::NotWritable("read-only".into())));
            }
        }
        if let Some(p) = e.child_text("pIsAvailable") {
            if self.get_at(port, p, depth + 1)? == 0.0 {
                return Err(error(
                    name,
                    NodeErrorKind::NotWritable(format!("not available now ({p} is 0)")),
                ));
            }
        }
        if let Some(p) = e.child_text("pIsLocked") {
            if self.get_at(port, p, depth + 1)? != 0.0 {
                return Err(error(
                    name,
                    NodeErrorKind::NotWritable(format!("locked ({p} is not 0; is the camera acquiring?)")),
                ));
            }
        }
        Ok(())
    }

    /// Writes a feature (an enumeration's integer, a boolean's 0 or 1).
    pub fn set(&self, port: &mut dyn Port, name: &str, value: f64) -> Result<(), NodeError> {
        self.set_at(port, name, value, 0)
    }

    fn set_at(&self, port: &mut dyn Port, name: &str, value: f64, depth: usize) -> Result<(), NodeError> {
        if depth > MAX_DEPTH {
            return Err(error(
                name,
                NodeErrorKind::Invalid("node references nested too deeply (a cycle?)".into()),
            ));
        }
        let e = self.node(name)?;
        self.writable(port, e, name, depth)?;
        match e.name.as_str() {
            "Integer" | "Float" | "Enumeration" | "Boolean" => {
                let raw = if e.name == "Boolean" {
                    let (on, off) = (
                        self.value_of(port, e, "OnValue", depth)?.unwrap_or(1.0),
                        self.value_of(port, e, "OffValue", depth)?.unwrap_or(0.0),
                    );
                    if value != 0.0 {
                        on
                    } else {
                        off
                    }
                } else {
                    value
                };
                match e.child_text("pValue") {
                    Some(p) => self.set_at(port, p, raw, depth + 1),
                    None if self.value_of(port, e, "Value", depth)? == Some(raw) => Ok(()),
                    None => Err(error(name, NodeErrorKind::NotWritable("a constant of the file".into()))),
                }
            }
            "IntReg" | "MaskedIntReg" | "FloatReg" => {
                let (address, len) = self.register(port, e, name, depth)?;
                let old = if e.name == "MaskedIntReg" {
                    port.read(address, len)
                        .map_err(|m| error(name, NodeErrorKind::Port(m)))?
                } else {
                    vec![0; len]
                };
                let bytes = encode(e, name, &old, value)?;
                port.write(address, &bytes)
                    .map_err(|m| error(name, NodeErrorKind::Port(m)))
            }
            "Converter" | "IntConverter" => {
                let to = self.formula(port, e, name, "FormulaTo", Some(("TO", value)), depth)?;
                self.set_at(port, child(e, name, "pValue")?, to, depth + 1)
            }
            "SwissKnife" | "IntSwissKnife" => Err(error(
                name,
                NodeErrorKind::NotWritable("computed (a SwissKnife)".into()),
            )),
            other => Err(error(name, NodeErrorKind::Unsupported(format!("node kind '{other}'")))),
        }
    }

    /// A feature's range and increment, as far as the file says and its nodes can be read.
    pub fn range(&self, port: &mut dyn Port, name: &str) -> (Option<f64>, Option<f64>, Option<f64>) {
        let Some(e) = self.nodes.get(name) else {
            return (None, None, None);
        };
        let mut get = |key: &str| self.value_of(port, e, key, 0).ok().flatten();
        let (min, max, inc) = (get("Min"), get("Max"), get("Inc"));
        if min.is_none() && max.is_none() && matches!(e.name.as_str(), "Integer" | "Float") {
            if let Some(p) = e.child_text("pValue") {
                return self.range(port, p);
            }
        }
        (min, max, inc)
    }

    /// An enumeration's entries: names and integer values.
    pub fn entries(&self, name: &str) -> Result<Vec<(String, f64)>, NodeError> {
        let e = self.node(name)?;
        if e.name != "Enumeration" {
            return Err(error(
                name,
                NodeErrorKind::Unsupported(format!("node kind '{}'", e.name)),
            ));
        }
        Ok(e.children_named("EnumEntry")
            .filter_map(|x| {
                Some((
                    x.attribute("Name")?.to_string(),
                    x.child_text("Value").and_then(number)?,
                ))
            })
            .collect())
    }

    /// An enumeration's current entry name (or its number, if no entry has it).
    pub fn get_entry(&self, port: &mut dyn Port, name: &str) -> Result<String, NodeError> {
        let v = self.get(port, name)?;
        Ok(self
            .entries(name)?
            .into_iter()
            .find(|(_, x)| *x == v)
            .map(|(n, _)| n)
            .unwrap_or_else(|| format!("{v}")))
    }

    /// Sets an enumeration to the entry of that name.
    pub fn set_entry(&self, port: &mut dyn Port, name: &str, entry: &str) -> Result<(), NodeError> {
        let entries = self.entries(name)?;
        let Some((_, v)) = entries.iter().find(|(n, _)| n == entry) else {
            let names: Vec<&str> = entries.iter().map(|(n, _)| n.as_str()).collect();
            return Err(error(
                name,
                NodeErrorKind::Invalid(format!("has no entry '{entry}' (it has: {})", names.join(", "))),
            ));
        };
        self.set(port, name, *v)
    }
}

fn child<'e>(e: &'e Element, name: &str, key: &str) -> Result<&'e str, NodeError> {
    e.child_text(key)
        .ok_or_else(|| error(name, NodeErrorKind::Invalid(format!("no <{key}>"))))
}

fn big_endian(e: &Element) -> bool {
    e.child_text("Endianess") == Some("BigEndian")
}

/// A masked register's bits as (shift from the value's bit 0, width), in the file's numbering:
/// bit 0 is the least significant for little-endian registers, the most significant for
/// big-endian ones.
fn bits(e: &Element, name: &str, len: usize) -> Result<(u32, u32), NodeError> {
    let n = |k: &str| e.child_text(k).and_then(number).map(|v| v as i64);
    let (lsb, msb) = match (n("Bit"), n("LSB"), n("MSB")) {
        (Some(b), _, _) => (b, b),
        (None, Some(l), Some(m)) => (l, m),
        _ => {
            return Err(error(
                name,
                NodeErrorKind::Invalid("a MaskedIntReg needs <Bit> or <LSB> and <MSB>".into()),
            ))
        }
    };
    let top = (len * 8) as i64 - 1;
    let (shift, width) = if big_endian(e) {
        (top - lsb, lsb - msb + 1)
    } else {
        (lsb, msb - lsb + 1)
    };
    if shift < 0 || width < 1 || shift + width > top + 1 {
        return Err(error(name, NodeErrorKind::Invalid("bits outside the register".into())));
    }
    Ok((shift as u32, width as u32))
}

fn to_u64(e: &Element, bytes: &[u8]) -> u64 {
    let mut a = [0u8; 8];
    if big_endian(e) {
        a[8 - bytes.len()..].copy_from_slice(bytes);
        u64::from_be_bytes(a)
    } else {
        a[..bytes.len()].copy_from_slice(bytes);
        u64::from_le_bytes(a)
    }
}

fn from_u64(e: &Element, v: u64, len: usize) -> Vec<u8> {
    if big_endian(e) {
        v.to_be_bytes()[8 - len..].to_vec()
    } else {
        v.to_le_bytes()[..len].to_vec()
    }
}

fn signed(e: &Element) -> bool {
    e.child_text("Sign") == Some("Signed")
}

fn decode(e: &Element, name: &str, bytes: &[u8]) -> Result<f64, NodeError> {
    let raw = to_u64(e, bytes);
    let (shift, width) = match e.name.as_str() {
        "FloatReg" => {
            return match bytes.len() {
                4 => Ok(f64::from(f32::from_bits(raw as u32))),
                8 => Ok(f64::from_bits(raw)),
                n => Err(error(
                    name,
                    NodeErrorKind::Invalid(format!("a float register of {n} bytes")),
                )),
            }
        }
        "MaskedIntReg" => bits(e, name, bytes.len())?,
        _ => (0, bytes.len() as u32 * 8),
    };
    let v = if width >= 64 {
        raw
    } else {
        (raw >> shift) & ((1u64 << width) - 1)
    };
    if signed(e) && width < 64 && v & (1 << (width - 1)) != 0 {
        return Ok((v as i64 - (1i64 << width)) as f64);
    }
    Ok(if signed(e) { v as i64 as f64 } else { v as f64 })
}

fn encode(e: &Element, name: &str, old: &[u8], value: f64) -> Result<Vec<u8>, NodeError> {
    let len = old.len();
    if e.name == "FloatReg" {
        return match len {
            4 => Ok(from_u64(e, u64::from((value as f32).to_bits()), 4)),
            8 => Ok(from_u64(e, value.to_bits(), 8)),
            n => Err(error(
                name,
                NodeErrorKind::Invalid(format!("a float register of {n} bytes")),
            )),
        };
    }
    let (shift, width) = if e.name == "MaskedIntReg" {
        bits(e, name, len)?
    } else {
        (0, len as u32 * 8)
    };
    let v = value.round();
    let (lo, hi) = if signed(e) {
        (-(2f64.powi(width as i32 - 1)), 2f64.powi(width as i32 - 1) - 1.0)
    } else {
        (0.0, 2f64.powi(width as i32) - 1.0)
    };
    if !(lo..=hi).contains(&v) {
        return Err(error(
            name,
            NodeErrorKind::Invalid(format!("{v} does not fit its {width} bits")),
        ));
    }
    let field = (v as i64 as u64) & if width >= 64 { u64::MAX } else { (1u64 << width) - 1 };
    let mask = if width >= 64 {
        u64::MAX
    } else {
        ((1u64 << width) - 1) << shift
    };
    let word = (to_u64(e, old) & !mask) | (field << shift);
    Ok(from_u64(e, word, len))
}
