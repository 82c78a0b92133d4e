//! Text formatting shared by the Markdown and CSV outputs: fixed-decimal numbers (no `-0.000`),
//! the paper's planning-time bins, family display names, GitHub pipe tables and CSV lines.
//! Everything here is a pure function of its arguments, so outputs are byte-reproducible.

/// `v` with `decimals` decimals; a result that rounds to zero is written without a sign, and a
/// non-finite value as `—`.
pub fn fixed(v: f64, decimals: usize) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// [`fixed`] for an optional value (`—` when absent).
pub fn fixed_opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(|| "—".into(), |v| fixed(v, decimals))
}

/// A value for CSV: 6 decimals (enough for fractions, views, path costs; runtime to the
/// microsecond), empty when absent or not finite.
pub fn csv_num(v: Option<f64>) -> String {
    csv_decimals(v, 6)
}

/// A value for CSV with `decimals` decimals (Chamfer distances, in units², need more than 6).
pub fn csv_decimals(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) if v.is_finite() => fixed(v, decimals),
        _ => String::new(),
    }
}

/// The time bins of the paper's Tables 2 and 3 (seconds), lower bound inclusive: `<0.1`,
/// `0.1–0.5`, `0.5–1`, `1–3`, `3–5` (5 included), `>5`.
pub const TIME_BINS: [&str; 6] = ["<0.1", "0.1–0.5", "0.5–1", "1–3", "3–5", ">5"];

/// The bin of a planning time in seconds (`—` when not finite).
pub fn time_bin(seconds: f64) -> &'static str {
    if !seconds.is_finite() {
        "—"
    } else if seconds < 0.1 {
        TIME_BINS[0]
    } else if seconds < 0.5 {
        TIME_BINS[1]
    } else if seconds < 1.0 {
        TIME_BINS[2]
    } else if seconds < 3.0 {
        TIME_BINS[3]
    } else if seconds <= 5.0 {
        TIME_BINS[4]
    } else {
        TIME_BINS[5]
    }
}

/// Display name of a family: `classical` → `Classical`, `some_thing` → `Some thing`.
pub fn family_title(family: &str) -> String {
    let spaced = family.replace('_', " ");
    let mut chars = spaced.chars();
    match chars.next() {
        Some(c) => c.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

/// Report order of families: classical, learned, hybrid, baseline, oracle, then others by name.
pub fn family_rank(family: &str) -> usize {
    match family {
        "classical" => 0,
        "learned" => 1,
        "hybrid" => 2,
        "baseline" => 3,
        "oracle" => 4,
        _ => 5,
    }
}

/// Column alignment of a Markdown table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Align {
    /// Text columns.
    Left,
    /// Number columns.
    Right,
}

/// A cell for a pipe table: `|` escaped, line breaks flattened.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// A GitHub pipe table (header, alignment row, rows), each line ending with a newline.
pub fn markdown_table(headers: &[(&str, Align)], rows: &[Vec<String>]) -> String {
    let mut out = String::new();
    let line = |cells: Vec<String>| format!("| {} |\n", cells.join(" | "));
    out.push_str(&line(headers.iter().map(|(h, _)| md_cell(h)).collect()));
    out.push_str(&line(
        headers
            .iter()
            .map(|(_, a)| match a {
                Align::Left => ":---".to_string(),
                Align::Right => "---:".to_string(),
            })
            .collect(),
    ));
    for r in rows {
        out.push_str(&line(r.iter().map(|c| md_cell(c)).collect()));
    }
    out
}

/// A CSV field: quoted when it holds a comma, quote or line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A CSV document: header line, then rows; `\n` line ends.
pub fn csv(headers: &[String], rows: &[Vec<String>]) -> String {
    let mut out = String::new();
    for r in std::iter::once(headers).chain(rows.iter().map(Vec::as_slice)) {
        out.push_str(&r.iter().map(|c| csv_field(c)).collect::<Vec<_>>().join(","));
        out.push('\n');
    }
    out
}

/// `1 episode`, `2 episodes`: `n` and `word`, with an `s` unless `n` is 1.
pub fn plural(n: usize, word: &str) -> String {
    if n == 1 {
        format!("{n} {word}")
    } else {
        format!("{n} {word}s")
    }
}

/// A file-name-safe version of a view-space name (`[A-Za-z0-9_-]`, others → `_`).
pub fn file_safe(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_drops_the_sign_of_zero() {
        assert_eq!(fixed(-0.0001, 3), "0.000");
        assert_eq!(fixed(-0.0031, 3), "-0.003");
        assert_eq!(fixed(0.99951, 3), "1.000");
        assert_eq!(fixed(25.655, 2), "25.66");
        assert_eq!(fixed(f64::NAN, 2), "—");
        assert_eq!(fixed_opt(None, 1), "—");
        assert_eq!(csv_num(Some(0.5)), "0.500000");
        assert_eq!(csv_num(None), "");
        assert_eq!(csv_decimals(Some(1.234e-5), 9), "0.000012340");
    }

    #[test]
    fn time_bins_follow_the_paper() {
        let got: Vec<&str> = [0.0, 0.099, 0.1, 0.49, 0.5, 0.99, 1.0, 2.99, 3.0, 5.0, 5.01, f64::NAN]
            .iter()
            .map(|&v| time_bin(v))
            .collect();
        assert_eq!(
            got,
            ["<0.1", "<0.1", "0.1–0.5", "0.1–0.5", "0.5–1", "0.5–1", "1–3", "1–3", "3–5", "3–5", ">5", "—"]
        );
    }

    #[test]
    fn families_tables_and_csv() {
        assert_eq!(family_title("classical"), "Classical");
        assert_eq!(family_title("some_thing"), "Some thing");
        assert_eq!(family_title(""), "");
        let t = markdown_table(&[("a", Align::Left), ("b", Align::Right)], &[vec!["x|y".into(), "1".into()]]);
        assert_eq!(t, "| a | b |\n| :--- | ---: |\n| x\\|y | 1 |\n");
        let c = csv(&["a".into(), "b".into()], &[vec!["1,2".into(), "say \"hi\"".into()]]);
        assert_eq!(c, "a,b\n\"1,2\",\"say \"\"hi\"\"\"\n");
        assert_eq!(file_safe("my space/2"), "my_space_2");
        assert_eq!(
            (plural(1, "run"), plural(0, "run"), plural(2, "run")),
            ("1 run".into(), "0 runs".into(), "2 runs".into())
        );
    }
}
