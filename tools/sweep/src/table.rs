//! The equal-time and equal-error summaries of a sweep ([`summaries`]), as tables printed in Markdown and shown in
//! the report as HTML ([`Table`]).

use crate::curve::{Curve, common_times, error_at, error_levels, time_to};
use photon_coordinator::out::report::sig;

/// A table of the methods against a few columns: the equal-time and equal-error summaries, printed as Markdown
/// ([`Table::markdown`]) and shown in the report as HTML ([`Table::html`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Table {
    /// Headings and one row of cells per method.
    Cells {
        /// `method`, then one heading per column.
        head: Vec<String>,
        /// Per method its name, then its cells.
        rows: Vec<Vec<String>>,
    },
    /// Why there is nothing to compare.
    Empty(&'static str),
}

impl Table {
    /// The methods of `curves` against `columns`, cells from `cell` (the curve and the column's index).
    fn new(curves: &[Curve], columns: Vec<String>, cell: impl Fn(&Curve, usize) -> String) -> Table {
        let rows = curves
            .iter()
            .map(|c| {
                std::iter::once(c.method.name().to_owned()).chain((0..columns.len()).map(|i| cell(c, i))).collect()
            })
            .collect();
        Table::Cells { head: [vec!["method".to_owned()], columns].concat(), rows }
    }

    /// The table in Markdown (numbers right-aligned), or its reason in parentheses.
    pub fn markdown(&self) -> String {
        match self {
            Table::Empty(why) => format!("({why})\n"),
            Table::Cells { head, rows } => {
                let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
                let rule = format!("|---|{}\n", "---:|".repeat(head.len().saturating_sub(1)));
                [line(head), rule].into_iter().chain(rows.iter().map(|r| line(r))).collect()
            }
        }
    }

    /// The table as an HTML `<table>`, or its reason as a `<p class="note">`; every text escaped.
    pub fn html(&self) -> String {
        match self {
            Table::Empty(why) => format!("<p class=\"note\">{}</p>\n", escape(why)),
            Table::Cells { head, rows } => {
                let line = |tag: &str, cells: &[String]| {
                    let cells: String = cells.iter().map(|c| format!("<{tag}>{}</{tag}>", escape(c))).collect();
                    format!("<tr>{cells}</tr>\n")
                };
                let body: String = rows.iter().map(|r| line("td", r)).collect();
                format!("<table>\n{}{body}</table>\n", line("th", head))
            }
        }
    }
}

/// The equal-time table: each method's relMSE at times inside every method's range.
pub fn equal_time(curves: &[Curve]) -> Table {
    let times = common_times(curves, 4);
    if times.is_empty() {
        return Table::Empty("no time lies inside every method's measured range: widen --budget");
    }
    let columns = times.iter().map(|t| format!("relMSE at {} s", sig(*t))).collect();
    Table::new(curves, columns, |c, i| error_at(c, times[i]).map_or_else(|| "—".into(), sig))
}

/// The equal-error table: seconds each method needs to reach a few relMSE levels.
pub fn equal_error(curves: &[Curve]) -> Table {
    let levels = error_levels(curves, 4);
    if levels.is_empty() {
        return Table::Empty("all errors are equal: no levels to compare");
    }
    let columns = levels.iter().map(|e| format!("s to relMSE {}", sig(*e))).collect();
    Table::new(curves, columns, |c, i| time_to(c, levels[i]).map_or_else(|| "—".into(), sig))
}

/// The summaries of a sweep, each with its heading: [`equal_time`] and [`equal_error`].
pub fn summaries(curves: &[Curve]) -> [(&'static str, Table); 2] {
    [
        ("equal time (relMSE, log-log interpolation)", equal_time(curves)),
        ("equal error (seconds, log-log interpolation; — out of the measured range)", equal_error(curves)),
    ]
}

/// `text` safe inside HTML text and quoted attribute values: `&`, `<`, `>`, `"` and `'` as character references.
pub fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curve::curves;
    use crate::fixtures::{curve, two_methods};

    #[test]
    fn equal_time_uses_only_the_common_range() {
        let a = curve(&[(1.0, 1.0), (10.0, 0.1)]);
        let b = curve(&[(2.0, 0.5), (20.0, 0.05)]);
        let t = common_times(&[a.clone(), b.clone()], 3);
        assert_eq!(t.len(), 3);
        assert!((t[0] - 2.0).abs() < 1e-12 && (t[2] - 10.0).abs() < 1e-9);
        assert!(common_times(&[a, curve(&[(11.0, 1.0), (12.0, 0.5)])], 3).is_empty());
        let table = equal_time(&[b]).markdown();
        assert_eq!(table.lines().count(), 3, "{table}");
    }

    #[test]
    fn html_tables_hold_the_cells_of_the_printed_ones() {
        for (heading, table) in summaries(&curves(&two_methods())) {
            let (md, html) = (table.markdown(), table.html());
            assert_eq!(html.matches("<table>").count(), 1, "{heading}: {html}");
            // Every cell of the Markdown table, headings and the method column included, is a cell of the HTML.
            let cells: Vec<&str> =
                md.lines().filter(|l| !l.starts_with("|---")).flat_map(|l| l.split('|')).map(str::trim).collect();
            let cells: Vec<&str> = cells.into_iter().filter(|c| !c.is_empty()).collect();
            assert_eq!(cells.len(), 3 * 5, "{heading}: {md}");
            for c in cells {
                assert!(html.contains(&format!(">{}</t", escape(c))), "{heading}: {c} missing from {html}");
            }
        }
        let empty = equal_time(&[curve(&[(1.0, 1.0), (2.0, 0.5)]), curve(&[(3.0, 1.0), (4.0, 0.5)])]);
        assert!(empty.markdown().starts_with("(no time"), "{}", empty.markdown());
        assert!(empty.html().starts_with("<p class=\"note\">no time") && !empty.html().contains("<table>"));
    }
}
