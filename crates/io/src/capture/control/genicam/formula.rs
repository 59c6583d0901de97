//! GenICam formulas: the expressions of `SwissKnife`, `IntSwissKnife`, `Converter` and
//! `IntConverter` nodes.
//!
//! In: a formula's text and the values of its variables (already read from their nodes). Out:
//! its value, or one line naming what is not understood. Numbers are `f64` (integers exact to
//! 2^53), as the float nodes are; the bitwise operators work on their `i64` values.
//!
//! Supported: decimal and `0x` hexadecimal numbers; variables (letters, digits, `_`, `.`);
//! `PI`, `E`; unary `-`, `+`, `~`, `!`; `**`; `*`, `/`, `%`; `+`, `-`; `<<`, `>>`; `<`, `>`, `<=`,
//! `>=`; `=`, `<>`; `&`; `^`; `|`; `&&`; `||`; `? :`; and the functions `ABS`, `SQRT`, `EXP`, `LN`,
//! `LG`, `SIN`, `COS`, `TAN`, `ATAN`, `SGN`, `NEG`, `TRUNC`, `FLOOR`, `CEIL` and `ROUND(x[, n])`.
//! Anything else is an error naming it.

/// Deepest nesting of parentheses and operators (a bound on the parser's recursion).
const MAX_DEPTH: usize = 64;

#[derive(Debug, Clone, PartialEq)]
enum Token {
    Num(f64),
    Name(String),
    Op(&'static str),
}

const OPS: [&str; 25] = [
    "**", "<<", ">>", "<=", ">=", "<>", "&&", "||", "(", ")", ",", "+", "-", "*", "/", "%", "<", ">", "=", "&", "|",
    "^", "~", "?", ":",
];

fn tokens(text: &str) -> Result<Vec<Token>, String> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || (c == b'.' && b.get(i + 1).is_some_and(u8::is_ascii_digit)) {
            let start = i;
            if c == b'0' && matches!(b.get(i + 1), Some(b'x' | b'X')) {
                i += 2;
                while i < b.len() && b[i].is_ascii_hexdigit() {
                    i += 1;
                }
                let v = u64::from_str_radix(&text[start + 2..i], 16)
                    .map_err(|_| format!("bad number '{}'", &text[start..i]))?;
                out.push(Token::Num(v as f64));
                continue;
            }
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            if i < b.len()
                && (b[i] == b'e' || b[i] == b'E')
                && b.get(i + 1)
                    .is_some_and(|n| n.is_ascii_digit() || *n == b'-' || *n == b'+')
            {
                i += 2;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
            let v: f64 = text[start..i]
                .parse()
                .map_err(|_| format!("bad number '{}'", &text[start..i]))?;
            out.push(Token::Num(v));
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'.') {
                i += 1;
            }
            out.push(Token::Name(text[start..i].to_string()));
        } else if let Some(op) = OPS.iter().find(|op| text[i..].starts_with(**op)) {
            out.push(Token::Op(op));
            i += op.len();
        } else if c == b'!' {
            out.push(Token::Op("!"));
            i += 1;
        } else {
            return Err(format!("unexpected '{}'", &text[i..].chars().next().unwrap_or('?')));
        }
    }
    Ok(out)
}

/// Binary operators by precedence, loosest first.
const LEVELS: [&[&str]; 10] = [
    &["||"],
    &["&&"],
    &["|"],
    &["^"],
    &["&"],
    &["=", "<>"],
    &["<", ">", "<=", ">="],
    &["<<", ">>"],
    &["+", "-"],
    &["*", "/", "%"],
];

struct Parser<'a> {
    tokens: Vec<Token>,
    at: usize,
    vars: &'a dyn Fn(&str) -> Option<f64>,
    depth: usize,
}

fn truth(x: f64) -> bool {
    x != 0.0
}

impl Parser<'_> {
    fn peek_op(&self) -> Option<&'static str> {
        match self.tokens.get(self.at) {
            Some(Token::Op(op)) => Some(op),
            _ => None,
        }
    }

    fn expect(&mut self, op: &str) -> Result<(), String> {
        if self.peek_op() == Some(op) {
            self.at += 1;
            Ok(())
        } else {
            Err(format!("expected '{op}'"))
        }
    }

    fn deeper(&mut self) -> Result<(), String> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err("nested too deeply".into());
        }
        Ok(())
    }

    fn ternary(&mut self) -> Result<f64, String> {
        self.deeper()?;
        let c = self.binary(0)?;
        let v = if self.peek_op() == Some("?") {
            self.at += 1;
            let a = self.ternary()?;
            self.expect(":")?;
            let b = self.ternary()?;
            if truth(c) {
                a
            } else {
                b
            }
        } else {
            c
        };
        self.depth -= 1;
        Ok(v)
    }

    fn binary(&mut self, level: usize) -> Result<f64, String> {
        if level == LEVELS.len() {
            return self.power();
        }
        let mut left = self.binary(level + 1)?;
        while let Some(op) = self.peek_op().filter(|op| LEVELS[level].contains(op)) {
            self.at += 1;
            let right = self.binary(level + 1)?;
            let (l, r) = (left as i64, right as i64);
            left = match op {
                "||" => f64::from(u8::from(truth(left) || truth(right))),
                "&&" => f64::from(u8::from(truth(left) && truth(right))),
                "|" => (l | r) as f64,
                "^" => (l ^ r) as f64,
                "&" => (l & r) as f64,
                "=" => f64::from(u8::from(left == right)),
                "<>" => f64::from(u8::from(left != right)),
                "<" => f64::from(u8::from(left < right)),
                ">" => f64::from(u8::from(left > right)),
                "<=" => f64::from(u8::from(left <= right)),
                ">=" => f64::from(u8::from(left >= right)),
                "<<" => l.checked_shl(r.clamp(0, 63) as u32).unwrap_or(0) as f64,
                ">>" => l.checked_shr(r.clamp(0, 63) as u32).unwrap_or(0) as f64,
                "+" => left + right,
                "-" => left - right,
                "*" => left * right,
                "/" => left / right,
                _ => left % right,
            };
        }
        Ok(left)
    }

    fn power(&mut self) -> Result<f64, String> {
        let base = self.unary()?;
        if self.peek_op() == Some("**") {
            self.at += 1;
            self.deeper()?;
            let exp = self.power()?;
            self.depth -= 1;
            return Ok(base.powf(exp));
        }
        Ok(base)
    }

    fn unary(&mut self) -> Result<f64, String> {
        match self.peek_op() {
            Some(op @ ("-" | "+" | "~" | "!")) => {
                self.at += 1;
                self.deeper()?;
                let v = self.unary()?;
                self.depth -= 1;
                Ok(match op {
                    "-" => -v,
                    "+" => v,
                    "~" => !(v as i64) as f64,
                    _ => f64::from(u8::from(!truth(v))),
                })
            }
            _ => self.atom(),
        }
    }

    fn atom(&mut self) -> Result<f64, String> {
        let token = self.tokens.get(self.at).cloned().ok_or("the formula ends early")?;
        self.at += 1;
        match token {
            Token::Num(v) => Ok(v),
            Token::Op("(") => {
                let v = self.ternary()?;
                self.expect(")")?;
                Ok(v)
            }
            Token::Op(op) => Err(format!("unexpected '{op}'")),
            Token::Name(name) => {
                if self.peek_op() == Some("(") {
                    self.at += 1;
                    let mut args = vec![self.ternary()?];
                    while self.peek_op() == Some(",") {
                        self.at += 1;
                        args.push(self.ternary()?);
                    }
                    self.expect(")")?;
                    return function(&name, &args);
                }
                match name.as_str() {
                    "PI" => Ok(std::f64::consts::PI),
                    "E" => Ok(std::f64::consts::E),
                    _ => (self.vars)(&name).ok_or_else(|| format!("unknown variable '{name}'")),
                }
            }
        }
    }
}

fn function(name: &str, args: &[f64]) -> Result<f64, String> {
    let x = args[0];
    let one = |v: f64| {
        if args.len() == 1 {
            Ok(v)
        } else {
            Err(format!("{name} takes one argument"))
        }
    };
    match name.to_ascii_uppercase().as_str() {
        "ABS" => one(x.abs()),
        "SQRT" => one(x.sqrt()),
        "EXP" => one(x.exp()),
        "LN" => one(x.ln()),
        "LG" => one(x.log10()),
        "SIN" => one(x.sin()),
        "COS" => one(x.cos()),
        "TAN" => one(x.tan()),
        "ATAN" => one(x.atan()),
        "SGN" => one(if x > 0.0 {
            1.0
        } else if x < 0.0 {
            -1.0
        } else {
            0.0
        }),
        "NEG" => one(-x),
        "TRUNC" => one(x.trunc()),
        "FLOOR" => one(x.floor()),
        "CEIL" => one(x.ceil()),
        "ROUND" => {
            let digits = args.get(1).copied().unwrap_or(0.0).clamp(0.0, 15.0);
            let scale = 10f64.powi(digits as i32);
            Ok((x * scale).round() / scale)
        }
        _ => Err(format!("unknown function '{name}'")),
    }
}

/// The value of `formula` with variables from `vars` (see the module doc).
pub fn evaluate(formula: &str, vars: &dyn Fn(&str) -> Option<f64>) -> Result<f64, String> {
    let mut p = Parser {
        tokens: tokens(formula)?,
        at: 0,
        vars,
        depth: 0,
    };
    let v = p.ternary()?;
    if p.at != p.tokens.len() {
        return Err(format!("unexpected text after position {}", p.at));
    }
    Ok(v)
}

/// The variable names a formula uses (to read only those nodes).
pub fn variables(formula: &str) -> Result<Vec<String>, String> {
    let t = tokens(formula)?;
    Ok(t.iter()
        .enumerate()
        .filter_map(|(i, tok)| match tok {
            Token::Name(n) if t.get(i + 1) != Some(&Token::Op("(")) && n != "PI" && n != "E" => Some(n.clone()),
            _ => None,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(f: &str) -> Result<f64, String> {
        evaluate(f, &|n| match n {
            "TO" => Some(12.5),
            "FROM" => Some(0x40 as f64),
            "VAR" => Some(3.0),
            _ => None,
        })
    }

    #[test]
    fn formulas_follow_genicams_precedence() {
        assert_eq!(eval("1 + 2 * 3").unwrap(), 7.0);
        assert_eq!(eval("(1 + 2) * 3").unwrap(), 9.0);
        assert_eq!(eval("2 ** 3 ** 2").unwrap(), 512.0);
        assert_eq!(eval("TO * 1000 / 10").unwrap(), 1250.0);
        assert_eq!(eval("(FROM >> 4) & 0x3").unwrap(), 0.0);
        assert_eq!(eval("FROM | 1 << 2").unwrap(), 68.0);
        assert_eq!(eval("VAR > 2 ? TO : 0").unwrap(), 12.5);
        assert_eq!(eval("VAR = 3 && VAR <> 4").unwrap(), 1.0);
        assert_eq!(eval("ROUND(TO / 4, 1)").unwrap(), 3.1);
        assert_eq!(eval("TRUNC(TO) + CEIL(0.2) + ABS(-1)").unwrap(), 14.0);
        assert_eq!(eval("7 % 4").unwrap(), 3.0);
        assert_eq!(eval("1.5e3").unwrap(), 1500.0);
        for bad in ["1 +", "FOO + 1", "MAX(1, 2)", "1 $ 2", "(1", "1 2"] {
            assert!(eval(bad).is_err(), "{bad}");
        }
        assert_eq!(variables("TO * VAR + ROUND(FROM)").unwrap(), vec!["TO", "VAR", "FROM"]);
    }

    #[test]
    fn any_text_is_a_value_or_an_error_never_a_panic() {
        let pieces = [
            "(", ")", "-", "**", "?", ":", "1", "0x", "VAR", "ROUND(", ",", "<<", "99", "~", "!", ".",
        ];
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..3000 {
            let mut text = String::new();
            for _ in 0..seed % 12 {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                text.push_str(pieces[(seed % pieces.len() as u64) as usize]);
            }
            seed = seed.wrapping_add(1);
            let _ = eval(&text);
            let _ = variables(&text);
        }
        // Nesting past the bound is an error, not a stack overflow.
        assert!(eval(&"(".repeat(100_000)).is_err());
        assert!(eval(&"-".repeat(100_000)).is_err());
    }
}
