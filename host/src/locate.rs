//! Where a field of a JSON document is: the line of the value at a field
//! path such as `goals[2].target[1]`, so that an error found after parsing
//! (an unknown segment, a negative weight) can still name its line.
//!
//! The text is assumed to be valid JSON (it has already been parsed); on
//! anything unexpected the search gives up and returns `None`. Object keys
//! are compared as written between their quotes (keys with escapes are not
//! matched).

/// One step of a field path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step<'p> {
    /// An object member.
    Key(&'p str),
    /// An array element.
    Index(usize),
}

/// The 1-based line on which the value at `path` starts, or of the deepest
/// part of the path that exists. `path` is dotted keys with `[n]` indices;
/// `""` or `"(top level)"` is the whole document.
#[must_use]
pub fn line(text: &str, path: &str) -> usize {
    let offset = offset(text.as_bytes(), &steps(path));
    1 + text
        .as_bytes()
        .get(..offset)
        .map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
}

/// Splits `a.b[3].c` into steps.
fn steps(path: &str) -> Vec<Step<'_>> {
    let mut out = Vec::new();
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let (key, indices) = part.split_once('[').unwrap_or((part, ""));
        if !key.is_empty() && key != "(top level)" {
            out.push(Step::Key(key));
        }
        for index in indices.split('[') {
            if let Ok(i) = index.trim_end_matches(']').parse() {
                out.push(Step::Index(i));
            }
        }
    }
    out
}

/// Byte offset of the value at `steps` (or of the deepest one found).
fn offset(text: &[u8], steps: &[Step<'_>]) -> usize {
    let mut at = skip_ws(text, 0);
    for step in steps {
        match find(text, at, *step) {
            Some(next) => at = next,
            None => break,
        }
    }
    at
}

/// Offset of the member or element `step` of the container at `at`.
fn find(text: &[u8], at: usize, step: Step<'_>) -> Option<usize> {
    let (open, close) = match step {
        Step::Key(_) => (b'{', b'}'),
        Step::Index(_) => (b'[', b']'),
    };
    if text.get(at) != Some(&open) {
        return None;
    }
    let mut pos = skip_ws(text, at + 1);
    let mut index = 0;
    while text.get(pos).is_some_and(|&c| c != close) {
        let value = match step {
            Step::Key(key) => {
                let end = skip_string(text, pos)?;
                let name = text.get(pos + 1..end - 1)?;
                let colon = skip_ws(text, end);
                let value = skip_ws(text, colon + 1);
                if name == key.as_bytes() {
                    return Some(value);
                }
                value
            }
            Step::Index(i) if i == index => return Some(pos),
            Step::Index(_) => pos,
        };
        index += 1;
        pos = skip_ws(text, skip_value(text, value)?);
        if text.get(pos) == Some(&b',') {
            pos = skip_ws(text, pos + 1);
        }
    }
    None
}

fn skip_ws(text: &[u8], mut pos: usize) -> usize {
    while text.get(pos).is_some_and(u8::is_ascii_whitespace) {
        pos += 1;
    }
    pos
}

/// The offset just past the string starting at `pos`.
fn skip_string(text: &[u8], pos: usize) -> Option<usize> {
    if text.get(pos) != Some(&b'"') {
        return None;
    }
    let mut i = pos + 1;
    loop {
        match text.get(i)? {
            b'\\' => i += 2,
            b'"' => return Some(i + 1),
            _ => i += 1,
        }
    }
}

/// The offset just past the value starting at `pos`.
fn skip_value(text: &[u8], pos: usize) -> Option<usize> {
    match text.get(pos)? {
        b'"' => skip_string(text, pos),
        b'{' | b'[' => {
            let mut depth = 0usize;
            let mut i = pos;
            loop {
                match text.get(i)? {
                    b'"' => {
                        i = skip_string(text, i)?;
                        continue;
                    }
                    b'{' | b'[' => depth += 1,
                    b'}' | b']' => {
                        depth -= 1;
                        if depth == 0 {
                            return Some(i + 1);
                        }
                    }
                    _ => {}
                }
                i += 1;
            }
        }
        _ => {
            let mut i = pos;
            while text
                .get(i)
                .is_some_and(|c| !matches!(c, b',' | b'}' | b']') && !c.is_ascii_whitespace())
            {
                i += 1;
            }
            Some(i)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = r#"{
  "start": "rest",
  "goals": [
    {"segment": "a", "target": [1, 2, 3], "weight": 1},
    {
      "segment": "b \"quoted\" [x]",
      "target": [
        0,
        {"deep": [1]},
        2
      ],
      "weight": -1
    }
  ]
}"#;

    #[test]
    fn finds_the_line_of_each_field() {
        assert_eq!(line(DOC, "(top level)"), 1);
        assert_eq!(line(DOC, "start"), 2);
        assert_eq!(line(DOC, "goals"), 3);
        assert_eq!(line(DOC, "goals[0]"), 4);
        assert_eq!(line(DOC, "goals[0].weight"), 4);
        assert_eq!(line(DOC, "goals[1]"), 5);
        assert_eq!(line(DOC, "goals[1].segment"), 6);
        assert_eq!(line(DOC, "goals[1].target[1]"), 9);
        assert_eq!(line(DOC, "goals[1].target[2]"), 10);
        assert_eq!(line(DOC, "goals[1].weight"), 12);
    }

    #[test]
    fn a_missing_field_points_at_its_container() {
        assert_eq!(line(DOC, "goals[1].point"), 5);
        assert_eq!(line(DOC, "goals[7].target"), 3);
        assert_eq!(line(DOC, "nothing"), 1);
    }

    #[test]
    fn broken_text_never_panics() {
        for cut in 0..DOC.len() {
            let _ = line(&DOC[..cut], "goals[1].target[2]");
        }
        assert_eq!(line("", "a[0]"), 1);
        assert_eq!(line("[[[", "[0][0][5]"), 1);
    }
}
