//! Where a field is written in a scene file: the line of a dotted path such as `objects[3].radius`, found in
//! the spanned TOML document (`toml::de::DeTable`), so that a value the types accept but validation refuses is
//! reported at its line, as a syntax error is.

use toml::de::{DeTable, DeValue};

/// One step of a dotted field path: a table key or an array index.
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// Splits `objects[3].emission.radiance` into `objects`, `3`, `emission`, `radiance`. `None` when the path
/// is not of that form.
fn steps(field: &str) -> Option<Vec<Step<'_>>> {
    let mut out = Vec::new();
    for part in field.split('.') {
        let (key, mut rest) = part.split_once('[').map_or((part, ""), |(k, r)| (k, r));
        if !key.is_empty() {
            out.push(Step::Key(key));
        }
        while !rest.is_empty() {
            let (index, after) = rest.split_once(']')?;
            out.push(Step::Index(index.parse().ok()?));
            rest = after.strip_prefix('[').unwrap_or(after);
        }
    }
    Some(out)
}

/// The 1-based line of `field` in the TOML `text`: the line of its key, or of the deepest enclosing table or
/// array element that the file writes (a field left at its default has no line of its own). `None` when the
/// text does not parse or writes none of the path.
pub fn line_of(text: &str, field: &str) -> Option<usize> {
    let doc = DeTable::parse(text).ok()?;
    let steps = steps(field)?;
    let mut table: &DeTable<'_> = doc.get_ref();
    let mut value: Option<&DeValue<'_>> = None;
    let mut found: Option<usize> = None;
    for step in steps {
        let next = match (step, value) {
            (Step::Key(k), None) => {
                table.iter().find(|(key, _)| key.get_ref().as_ref() == k).map(|(key, v)| (key.span().start, v))
            }
            (Step::Key(k), Some(DeValue::Table(t))) => {
                t.iter().find(|(key, _)| key.get_ref().as_ref() == k).map(|(key, v)| (key.span().start, v))
            }
            (Step::Index(i), Some(DeValue::Array(a))) => a.get(i).map(|v| (v.span().start, v)),
            _ => None,
        };
        let Some((start, v)) = next else { break };
        found = Some(start);
        value = Some(v.get_ref());
        if let DeValue::Table(t) = v.get_ref() {
            table = t;
        }
    }
    found.map(|offset| 1 + text[..offset.min(text.len())].matches('\n').count())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "[camera]\neye = [0, 1, 3]\n\n[render]\nspp = 4\n\n[[objects]]\ntype = \"sphere\"\n\n[[objects]]\ntype = \"sphere\"\nradius = -1\nemission = { radiance = [1, 2, 3] }\n";

    #[test]
    fn finds_keys_array_elements_and_inline_tables() {
        assert_eq!(line_of(TEXT, "camera.eye"), Some(2));
        assert_eq!(line_of(TEXT, "render.spp"), Some(5));
        assert_eq!(line_of(TEXT, "objects[1].radius"), Some(12));
        assert_eq!(line_of(TEXT, "objects[1].emission.radiance"), Some(13));
    }

    #[test]
    fn a_default_field_takes_the_line_of_what_encloses_it() {
        // `objects[0]` writes no radius: the error points at the element's `[[objects]]` header.
        assert_eq!(line_of(TEXT, "objects[0].radius"), Some(7));
        assert_eq!(line_of(TEXT, "render.max_depth"), Some(4));
        assert_eq!(line_of(TEXT, "lights[0].position"), None);
        assert_eq!(line_of("not toml [", "camera.eye"), None);
    }
}
