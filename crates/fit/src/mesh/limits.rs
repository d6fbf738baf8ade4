//! What every format shares: the error constructors (every error names `mesh`), the clipping of
//! client text an error message repeats, the panic guard around third-party parsers, and the
//! coordinate parser of the text formats.

use crate::{Error, Result};
use sublevel_core::math::Real;

/// Bytes of client text an error message repeats.
const ECHO_BYTES: usize = 48;

/// Longest message taken from a third-party parser.
pub(super) const FOREIGN_MESSAGE_BYTES: usize = 160;

/// [`Error::InvalidArgument`] naming `mesh`.
pub(super) fn invalid(reason: impl Into<String>) -> Error {
    Error::invalid("mesh", reason)
}

/// [`Error::ResourceExhausted`] naming `mesh` (a count beyond `max_points`).
pub(super) fn exhausted(reason: String) -> Error {
    Error::ResourceExhausted(format!("`mesh`: {reason}"))
}

/// `s` cut to at most `max` bytes (at a character boundary), `…` appended when cut.
fn clip_to(s: &str, max: usize) -> String {
    if s.len() <= max {
        return s.to_owned();
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &s[..end])
}

/// Client text as an error message repeats it: at most [`ECHO_BYTES`].
pub(super) fn echo(s: &str) -> String {
    clip_to(s, ECHO_BYTES)
}

/// `one` when `n` is 1, else `many` ("1 byte", "2 bytes").
pub(super) fn plural(n: impl Into<u128>, one: &'static str, many: &'static str) -> &'static str {
    if n.into() == 1 {
        one
    } else {
        many
    }
}

/// Runs a third-party parser, turning a panic into an error naming `mesh`.
pub(super) fn guarded<T>(fmt: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err(invalid(format!("malformed {fmt} file (the parser gave up)"))))
}

/// The bytes of a text format as UTF-8.
pub(super) fn text<'a>(bytes: &'a [u8], fmt: &str) -> Result<&'a str> {
    std::str::from_utf8(bytes).map_err(|e| invalid(format!("{fmt} file is not UTF-8 text: {e}")))
}

/// One finite coordinate of a text format; the error names the format and the 1-based line.
pub(super) fn parse_coord(tok: Option<&str>, line: usize, fmt: &str) -> Result<Real> {
    let tok = tok.ok_or_else(|| invalid(format!("{fmt} line {line}: expected 3 coordinates")))?;
    let v: Real = tok.parse().map_err(|_| invalid(format!("{fmt} line {line}: `{}` is not a number", echo(tok))))?;
    if !v.is_finite() {
        return Err(invalid(format!("{fmt} line {line}: coordinate `{}` is not finite", echo(tok))));
    }
    Ok(v)
}

/// A third-party parser's message as a plain sentence: Rust `Debug` lists of strings (stl_io
/// prints tokens as `["outer", "loop"]`) become `` `outer loop` ``, and the whole is cut to
/// [`FOREIGN_MESSAGE_BYTES`] (the tokens are the client's text).
pub(super) fn foreign_message(msg: &str) -> String {
    let mut out = String::with_capacity(msg.len().min(2 * FOREIGN_MESSAGE_BYTES));
    let mut rest = msg;
    while let Some(start) = rest.find('[') {
        out.push_str(&rest[..start]);
        match debug_string_list(&rest[start..]) {
            Some((words, used)) => {
                out.push('`');
                out.push_str(&words.join(" "));
                out.push('`');
                rest = &rest[start + used..];
            }
            None => {
                out.push('[');
                rest = &rest[start + 1..];
            }
        }
        if out.len() > FOREIGN_MESSAGE_BYTES {
            break;
        }
    }
    out.push_str(rest);
    clip_to(out.trim(), FOREIGN_MESSAGE_BYTES)
}

/// Parses a `Debug`-printed `[&str]` at the start of `s` (`["a", "b\"c"]`, `[]`): the strings
/// and the number of bytes used; `None` if `s` does not start with one.
fn debug_string_list(s: &str) -> Option<(Vec<String>, usize)> {
    let mut chars = s.char_indices().peekable();
    if chars.next()?.1 != '[' {
        return None;
    }
    let mut words = Vec::new();
    if let Some(&(i, ']')) = chars.peek() {
        return Some((words, i + 1));
    }
    loop {
        if chars.next()?.1 != '"' {
            return None;
        }
        let mut w = String::new();
        loop {
            match chars.next()?.1 {
                '"' => break,
                '\\' => w.push(chars.next()?.1),
                c => w.push(c),
            }
        }
        words.push(w);
        match chars.next()? {
            (i, ']') => return Some((words, i + 1)),
            (_, ',') if chars.next()?.1 == ' ' => {}
            _ => return None,
        }
    }
}
