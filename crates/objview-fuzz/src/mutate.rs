//! Seeded mutations: case `i` of a kind under a run seed is a seed of the corpus with a few
//! mutations drawn from its own [`Rng`] stream, so the same (seed, kind, i) always gives the
//! same bytes, whatever order or worker generates it.
//!
//! Mutations: bit flips, byte sets, inserted / deleted / duplicated chunks, truncation, splicing
//! with another seed, "interesting" integers (0, 1, -1, 2^31−1, 2^32−1, 2^63, 2^64−1, …) written
//! over binary header fields (known offsets of the format first: STL triangle count, GLB chunk
//! lengths, NPY header length, zip sizes and offsets, PCD compressed sizes), numeric tokens in
//! text replaced by hostile ones (huge counts, 1e400, nan, -0, negative indices), format
//! keywords inserted, and lines repeated.

use crate::corpus::{dictionary, Case};
use crate::kinds::Kind;
use crate::rng::Rng;
use serde_json::Value;

/// Largest mutated file (bytes); longer results are cut.
pub const MAX_LEN: usize = 1 << 20;

/// Integers written into binary fields.
const INTERESTING: &[u64] = &[
    0,
    1,
    2,
    3,
    0x7f,
    0x80,
    0xff,
    0x100,
    0x7fff,
    0x8000,
    0xffff,
    0x1_0000,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    0x1_0000_0000,
    0x7fff_ffff_ffff_ffff,
    0x8000_0000_0000_0000,
    u64::MAX,
    u64::MAX - 1,
];

/// Replacements of numeric tokens in text.
const TOKENS: &[&str] = &[
    "0",
    "1",
    "-1",
    "-0",
    "2",
    "3",
    "255",
    "256",
    "65536",
    "2147483647",
    "2147483648",
    "-2147483648",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999",
    "1000000000",
    "1e400",
    "-1e400",
    "1e-400",
    "1e308",
    "5e-324",
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "Infinity",
    "0.5",
    "-0.0",
    "-9999999",
    "0x10",
    "1e9",
    "+1",
    "1.",
    ".5",
    "",
];

/// The bytes of case `index` of `kind` under run seed `seed` (see the module docs). The first
/// `seeds.len()` cases are the seeds themselves.
pub fn make_case(kind: Kind, seed: u64, index: u64, seeds: &[Case]) -> Case {
    if (index as usize) < seeds.len() {
        return seeds[index as usize].clone();
    }
    let mut rng = Rng::for_case(seed, kind.name(), index);
    let mut case = rng.pick(seeds).clone();
    // Mostly the main file; sometimes a file it names (.mtl, .bin, texture, split's mesh).
    let target =
        if case.files.len() > 1 && rng.chance(1, 5) { rng.range(1, case.files.len() - 1) } else { 0 };
    let splice_from: Vec<&[u8]> =
        seeds.iter().filter_map(|c| c.files.get(target).map(|(_, b)| b.as_slice())).collect();
    let n = rng.small_len(8);
    let bytes = &mut case.files[target].1;
    for _ in 0..n {
        mutate_once(kind, bytes, &splice_from, &mut rng);
        bytes.truncate(MAX_LEN);
    }
    case
}

/// Applies one random mutation to `b`.
pub fn mutate_once(kind: Kind, b: &mut Vec<u8>, others: &[&[u8]], rng: &mut Rng) {
    // Weights of the mutations below; structural JSON edits only for JSON-based formats.
    let json = if is_json(kind) { 8 } else { 0 };
    let weights: [usize; 12] = [3, 2, 2, 2, 2, 1, 1, 4, 4, 2, 1, json];
    let total: usize = weights.iter().sum();
    let mut r = rng.below(total);
    let mut op = 0;
    while r >= weights[op] {
        r -= weights[op];
        op += 1;
    }
    let len = b.len();
    match op {
        // Bit flip.
        0 if len > 0 => {
            let p = rng.below(len);
            b[p] ^= 1 << rng.below(8);
        }
        // Byte set.
        1 if len > 0 => {
            let p = rng.below(len);
            let any = rng.below(256) as u8;
            b[p] = *rng.pick(&[0u8, 0xff, 0x7f, 0x80, b'\n', b'0', b'9', b'-', b'.', b' ', b'"', any]);
        }
        // Insert random bytes (or a run of one byte).
        2 => {
            let p = rng.below(len + 1);
            let n = rng.small_len(64);
            let chunk: Vec<u8> = if rng.chance(1, 2) {
                (0..n).map(|_| rng.below(256) as u8).collect()
            } else {
                vec![rng.below(256) as u8; n]
            };
            b.splice(p..p, chunk);
        }
        // Delete a chunk.
        3 if len > 0 => {
            let s = rng.below(len);
            let n = rng.small_len(len - s);
            b.drain(s..s + n);
        }
        // Duplicate a chunk, possibly several times.
        4 if len > 0 => {
            let s = rng.below(len);
            let n = rng.small_len((len - s).min(4096));
            let chunk = b[s..s + n].to_vec();
            let times = rng.small_len(16);
            let p = if rng.chance(1, 2) { s + n } else { rng.below(len + 1) };
            let rep: Vec<u8> = chunk.iter().copied().cycle().take(n * times).collect();
            b.splice(p..p, rep);
        }
        // Truncate.
        5 => b.truncate(rng.below(len + 1)),
        // Splice with another input of the kind.
        6 if !others.is_empty() => {
            let o = rng.pick(others);
            let a = rng.below(len + 1);
            let c = rng.below(o.len() + 1);
            b.truncate(a);
            b.extend_from_slice(&o[c..]);
        }
        // Interesting integer over a (header) field.
        7 if len > 0 => {
            let hot = hot_offsets(kind, b);
            let p = if !hot.is_empty() && rng.chance(1, 2) {
                *rng.pick(&hot)
            } else if rng.chance(2, 3) {
                rng.below(len.min(256))
            } else {
                rng.below(len)
            };
            let width = *rng.pick(&[1usize, 2, 4, 8]);
            let mut v = *rng.pick(INTERESTING);
            if rng.chance(1, 8) {
                v = v.wrapping_neg();
            }
            let bytes = if rng.chance(3, 4) { v.to_le_bytes() } else { v.to_be_bytes() };
            let src = if rng.chance(3, 4) { &bytes[..width] } else { &bytes[8 - width..] };
            for (k, &x) in src.iter().enumerate() {
                if let Some(d) = b.get_mut(p + k) {
                    *d = x;
                }
            }
        }
        // Numeric token replaced by a hostile one.
        8 => {
            let toks = numeric_tokens(b);
            if toks.is_empty() {
                return mutate_once(kind, b, others, rng);
            }
            let (s, e) = *rng.pick(&toks);
            let t = rng.pick(TOKENS).as_bytes().to_vec();
            b.splice(s..e, t);
        }
        // Format keyword inserted (at a line start half of the time).
        9 => {
            let word = rng.pick(dictionary(kind)).as_bytes().to_vec();
            let mut p = rng.below(len + 1);
            if rng.chance(1, 2) {
                p = b[..p].iter().rposition(|&c| c == b'\n').map_or(0, |i| i + 1);
            }
            b.splice(p..p, word);
        }
        // A line repeated.
        10 if len > 0 => {
            let p = rng.below(len);
            let s = b[..p].iter().rposition(|&c| c == b'\n').map_or(0, |i| i + 1);
            let e = b[p..].iter().position(|&c| c == b'\n').map_or(len, |i| p + i + 1);
            let line = b[s..e].to_vec();
            let times = rng.small_len(256);
            let rep: Vec<u8> = line.iter().copied().cycle().take(line.len() * times).collect();
            b.splice(e..e, rep);
        }
        // A structural edit of the JSON document (or of one JSON line, or of a GLB's JSON
        // chunk, lengths rebuilt).
        11 => {
            if !json_mutate(kind, b, rng) {
                let p = rng.below(len + 1);
                b.splice(p..p, rng.pick(dictionary(kind)).bytes());
            }
        }
        // The drawn mutation does not apply (empty input): insert instead.
        _ => {
            let p = rng.below(len + 1);
            let x = rng.below(256) as u8;
            b.insert(p, x);
        }
    }
}

/// Whether the kind's files are JSON (or JSON Lines, or carry a JSON chunk).
fn is_json(kind: Kind) -> bool {
    matches!(
        kind,
        Kind::Gltf | Kind::Glb | Kind::Rules | Kind::Split | Kind::Annotations | Kind::Resume | Kind::Results
    )
}

/// Numbers written into JSON values.
const JSON_NUMBERS: &[&str] = &[
    "0",
    "1",
    "-1",
    "-0.0",
    "2",
    "255",
    "65535",
    "4294967295",
    "4294967296",
    "2147483648",
    "9007199254740993",
    "18446744073709551615",
    "-9223372036854775808",
    "1e308",
    "-1e308",
    "5e-324",
    "0.5",
    "1e-7",
];

/// Structural JSON mutation of `b` (see [`mutate_once`]); false when nothing parses as JSON.
fn json_mutate(kind: Kind, b: &mut Vec<u8>, rng: &mut Rng) -> bool {
    if kind == Kind::Glb {
        return glb_json_mutate(b, rng);
    }
    if let Ok(mut v) = serde_json::from_slice::<Value>(b) {
        mutate_value(&mut v, rng);
        *b = to_json(&v, rng);
        return true;
    }
    // JSON Lines: one line that parses.
    let mut lines: Vec<Vec<u8>> = b.split(|&c| c == b'\n').map(<[u8]>::to_vec).collect();
    let ok: Vec<usize> = (0..lines.len())
        .filter(|&i| serde_json::from_slice::<Value>(&lines[i]).is_ok_and(|v| v.is_object()))
        .collect();
    if ok.is_empty() {
        return false;
    }
    let i = *rng.pick(&ok);
    let mut v: Value = serde_json::from_slice(&lines[i]).expect("checked above");
    mutate_value(&mut v, rng);
    lines[i] = serde_json::to_vec(&v).expect("a Value serializes");
    if rng.chance(1, 4) {
        // Duplicate the line (same key twice, more lines).
        let l = lines[i].clone();
        lines.insert(i, l);
    }
    *b = lines.join(&b'\n');
    true
}

fn to_json(v: &Value, rng: &mut Rng) -> Vec<u8> {
    if rng.chance(1, 2) {
        serde_json::to_vec(v).expect("a Value serializes")
    } else {
        serde_json::to_vec_pretty(v).expect("a Value serializes")
    }
}

/// The GLB's JSON chunk mutated, the container's lengths rebuilt.
fn glb_json_mutate(b: &mut Vec<u8>, rng: &mut Rng) -> bool {
    let Some(json_len) = u32_at(b, 12) else { return false };
    let Some(json) = b.get(20..20 + json_len) else { return false };
    let Ok(mut v) = serde_json::from_slice::<Value>(json) else { return false };
    let rest = b[(20 + json_len).div_ceil(4) * 4..].to_vec();
    mutate_value(&mut v, rng);
    let mut j = to_json(&v, rng);
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let total = 20 + j.len() + rest.len();
    let mut out = b[..12.min(b.len())].to_vec();
    out.resize(12, 0);
    out[8..12].copy_from_slice(&(total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(j);
    out.extend(rest);
    *b = out;
    true
}

fn count_nodes(v: &Value) -> usize {
    1 + match v {
        Value::Array(a) => a.iter().map(count_nodes).sum(),
        Value::Object(m) => m.values().map(count_nodes).sum(),
        _ => 0,
    }
}

fn count_strings(v: &Value) -> usize {
    match v {
        Value::String(_) => 1,
        Value::Array(a) => a.iter().map(count_strings).sum(),
        Value::Object(m) => m.values().map(count_strings).sum(),
        _ => 0,
    }
}

/// The `k`-th string value of `v` in pre-order.
fn nth_string_mut<'a>(v: &'a mut Value, k: &mut usize) -> Option<&'a mut String> {
    match v {
        Value::String(s) if *k == 0 => Some(s),
        Value::String(_) => {
            *k -= 1;
            None
        }
        Value::Array(a) => a.iter_mut().find_map(|x| nth_string_mut(x, k)),
        Value::Object(m) => m.values_mut().find_map(|x| nth_string_mut(x, k)),
        _ => None,
    }
}

/// The `k`-th node of `v` in pre-order.
fn nth_mut<'a>(v: &'a mut Value, k: &mut usize) -> Option<&'a mut Value> {
    if *k == 0 {
        return Some(v);
    }
    *k -= 1;
    match v {
        Value::Array(a) => a.iter_mut().find_map(|x| nth_mut(x, k)),
        Value::Object(m) => m.values_mut().find_map(|x| nth_mut(x, k)),
        _ => None,
    }
}

/// One structural edit at a random node: a hostile number, another type, a copied subtree, a
/// deleted or duplicated member, an extra index in an integer list, deep nesting.
fn mutate_value(root: &mut Value, rng: &mut Rng) {
    // A quarter of the time: a string value (names, ids, paths, modes) gets control characters
    // or odd characters, is emptied or repeated. (Never `..` or an absolute path: a case must
    // not reach outside its own folder.)
    let strings = count_strings(root);
    if strings > 0 && rng.chance(1, 4) {
        let mut k = rng.below(strings);
        if let Some(s) = nth_string_mut(root, &mut k) {
            let at =
                s.char_indices().map(|(i, _)| i).nth(rng.below(s.chars().count() + 1)).unwrap_or(s.len());
            match rng.below(4) {
                0 => s.insert(at, *rng.pick(&['\n', '\r', '\t', '\0', '\u{2028}', '#', '\''])),
                1 => {
                    let t: &&str = rng.pick(&["\n", "\\", ".", ":", "%20", "?"]);
                    s.insert_str(at, t)
                }
                2 => s.clear(),
                _ => *s = s.repeat(rng.small_len(64)),
            }
        }
        return;
    }
    let n = count_nodes(root);
    let donor = {
        let mut k = rng.below(n);
        nth_mut(root, &mut k).cloned().unwrap_or(Value::Null)
    };
    let mut k = rng.below(n);
    let Some(node) = nth_mut(root, &mut k) else { return };
    let number = |rng: &mut Rng| -> Value {
        let t: &&str = rng.pick(JSON_NUMBERS);
        serde_json::from_str(t).expect("valid JSON numbers")
    };
    match rng.below(9) {
        0 => *node = number(rng),
        // A key renamed (control characters, a near miss, empty).
        8 => match node {
            Value::Object(m) if !m.is_empty() => {
                let key = m.keys().nth(rng.below(m.len())).cloned().expect("index in range");
                let v = m.remove(&key).expect("present");
                let new = match rng.below(3) {
                    0 => format!("{key}\n"),
                    1 => key.to_uppercase(),
                    _ => String::new(),
                };
                m.insert(new, v);
            }
            other => *other = number(rng),
        },
        1 => {
            *node = match rng.below(8) {
                0 => Value::Null,
                1 => Value::Bool(true),
                2 => Value::String(String::new()),
                3 => Value::String("x".into()),
                4 => Value::Array(vec![]),
                5 => Value::Object(Default::default()),
                _ => donor,
            }
        }
        2 => *node = donor,
        3 => match node {
            Value::Array(a) if !a.is_empty() => {
                let i = rng.below(a.len());
                a.remove(i);
            }
            Value::Object(m) if !m.is_empty() => {
                let key = m.keys().nth(rng.below(m.len())).cloned().expect("index in range");
                m.remove(&key);
            }
            other => *other = number(rng),
        },
        4 => match node {
            Value::Array(a) if !a.is_empty() => {
                let x = a[rng.below(a.len())].clone();
                for _ in 0..rng.small_len(16) {
                    a.push(x.clone());
                }
            }
            Value::Object(m) => {
                let keys: Vec<&str> = [
                    "children",
                    "nodes",
                    "mesh",
                    "uri",
                    "count",
                    "byteOffset",
                    "byteStride",
                    "rules",
                    "error",
                    "uid",
                ]
                .to_vec();
                m.insert(rng.pick(&keys).to_string(), donor);
            }
            other => *other = Value::Array(vec![other.clone(), donor]),
        },
        // An index list grows (glTF children/nodes: shared subtrees, cycles, out of range).
        5 => match node {
            Value::Array(a) => {
                let len = a.len() as u64;
                for _ in 0..rng.small_len(8) {
                    let i = if rng.chance(1, 4) { len } else { rng.below(len as usize + 1) as u64 };
                    a.push(Value::from(i));
                }
            }
            other => *other = number(rng),
        },
        // Deep nesting.
        6 => {
            for _ in 0..rng.small_len(300) {
                let inner = std::mem::take(node);
                *node = if rng.chance(1, 2) {
                    Value::Array(vec![inner])
                } else {
                    serde_json::json!({ "rules": [inner] })
                };
            }
        }
        _ => match node {
            Value::String(s) => {
                *s = rng
                    .pick(&[
                        "",
                        "a.bin",
                        "tex.png",
                        "mesh.off",
                        "line\none",
                        "tab\tand\rreturn",
                        "data:application/octet-stream;base64,AAAA",
                        "\u{0}",
                        "auto",
                        "terminal",
                        "0",
                    ])
                    .to_string()
            }
            other => *other = number(rng),
        },
    }
}

/// Byte ranges of numeric-looking tokens (`-12`, `0.5e3`, `+.1`), at most 4096 of them.
pub fn numeric_tokens(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    let num_char = |c: u8| c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'+' | b'-');
    while i < b.len() && out.len() < 4096 {
        let starts = b[i].is_ascii_digit()
            || (matches!(b[i], b'-' | b'+' | b'.') && b.get(i + 1).is_some_and(|c| c.is_ascii_digit()));
        let after_word = i > 0 && (b[i - 1].is_ascii_alphabetic() || b[i - 1] == b'_');
        if starts && !after_word {
            let s = i;
            i += 1;
            while i < b.len() && num_char(b[i]) {
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

fn u32_at(b: &[u8], o: usize) -> Option<usize> {
    b.get(o..o + 4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
}

fn u16_at(b: &[u8], o: usize) -> Option<usize> {
    b.get(o..o + 2).map(|s| u16::from_le_bytes([s[0], s[1]]) as usize)
}

/// Offsets of binary header fields of the format (lengths, counts, offsets).
pub fn hot_offsets(kind: Kind, b: &[u8]) -> Vec<usize> {
    let find = |needle: &[u8]| b.windows(needle.len()).position(|w| w == needle);
    let mut out = Vec::new();
    match kind {
        Kind::Stl => out.push(80),
        Kind::Glb => {
            out.extend([4, 8, 12, 16]);
            if let Some(json_len) = u32_at(b, 12) {
                let bin = (20 + json_len).div_ceil(4) * 4;
                out.extend([bin, bin + 4]);
            }
        }
        Kind::Npy => out.extend([6, 8]),
        Kind::Npz => {
            let mut i = 0;
            while i + 4 <= b.len() && out.len() < 64 {
                match &b[i..i + 4] {
                    b"PK\x03\x04" => {
                        out.extend([i + 8, i + 18, i + 22, i + 26, i + 28]);
                        let data = i + 30 + u16_at(b, i + 26).unwrap_or(0) + u16_at(b, i + 28).unwrap_or(0);
                        out.extend([data, data + 6, data + 8]); // the NPY header inside (stored)
                    }
                    b"PK\x01\x02" => out.extend([i + 10, i + 20, i + 24, i + 28, i + 30, i + 42]),
                    b"PK\x05\x06" => out.extend([i + 8, i + 10, i + 12, i + 16, i + 20]),
                    _ => {}
                }
                i += 1;
            }
        }
        Kind::Pcd => {
            if let Some(p) = find(b"binary_compressed\n") {
                out.extend([p + 18, p + 22, p + 26]);
            }
        }
        Kind::Ply | Kind::CloudPly => {
            if let Some(p) = find(b"end_header\n") {
                out.extend([p + 11, p + 12, p + 19, p + 20]);
            }
        }
        _ => {}
    }
    out.retain(|&o| o < b.len());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::seeds;

    #[test]
    fn same_seed_same_cases_and_cases_differ() {
        for &kind in Kind::ALL {
            let s = seeds(kind);
            let n = s.len() as u64;
            for i in [n, n + 1, n + 7, n + 1000] {
                assert_eq!(make_case(kind, 42, i, &s), make_case(kind, 42, i, &s));
            }
            let distinct: std::collections::HashSet<Vec<u8>> =
                (n..n + 50).map(|i| make_case(kind, 42, i, &s).files.concat_bytes()).collect();
            assert!(distinct.len() > 40, "{}: {}", kind.name(), distinct.len());
            assert_eq!(make_case(kind, 42, 0, &s), s[0]);
        }
    }

    trait Concat {
        fn concat_bytes(&self) -> Vec<u8>;
    }
    impl Concat for Vec<(String, Vec<u8>)> {
        fn concat_bytes(&self) -> Vec<u8> {
            self.iter().flat_map(|(n, b)| n.bytes().chain(b.iter().copied())).collect()
        }
    }

    #[test]
    fn numeric_tokens_are_found() {
        let t = numeric_tokens(b"v 1 -2.5e3 x1 .5 abc +7\n3/4");
        let s: Vec<&[u8]> = t.iter().map(|&(a, b)| &b"v 1 -2.5e3 x1 .5 abc +7\n3/4"[a..b]).collect();
        assert_eq!(s, vec![&b"1"[..], b"-2.5e3", b".5", b"+7", b"3", b"4"]);
    }

    #[test]
    fn hot_offsets_point_into_headers() {
        let stl = &seeds(Kind::Stl)[1].files[0].1;
        assert_eq!(hot_offsets(Kind::Stl, stl), vec![80]);
        let npz = &seeds(Kind::Npz)[0].files[0].1;
        let h = hot_offsets(Kind::Npz, npz);
        assert!(h.len() > 10 && h.iter().all(|&o| o < npz.len()));
    }
}
