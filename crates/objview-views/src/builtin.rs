//! Shipped data built into the binary with `include_str!`: the `tammes-N` view sets of
//! `data/viewsets/` (SPEC §3; N = the saturation grid of SPEC §4), so no data files are needed
//! at run time. 128 and 360 are verbatim copies of the official files
//! (`data/viewsets/NOTICE-official.md`); the others are output of [`crate::tammes::generate`].

/// Every shipped `tammes-N` set: N and the file text, in increasing N.
pub const SHIPPED_TAMMES: &[(usize, &str)] = &[
    (6, include_str!("../../../data/viewsets/tammes-6.txt")),
    (8, include_str!("../../../data/viewsets/tammes-8.txt")),
    (10, include_str!("../../../data/viewsets/tammes-10.txt")),
    (12, include_str!("../../../data/viewsets/tammes-12.txt")),
    (14, include_str!("../../../data/viewsets/tammes-14.txt")),
    (16, include_str!("../../../data/viewsets/tammes-16.txt")),
    (20, include_str!("../../../data/viewsets/tammes-20.txt")),
    (24, include_str!("../../../data/viewsets/tammes-24.txt")),
    (28, include_str!("../../../data/viewsets/tammes-28.txt")),
    (32, include_str!("../../../data/viewsets/tammes-32.txt")),
    (40, include_str!("../../../data/viewsets/tammes-40.txt")),
    (48, include_str!("../../../data/viewsets/tammes-48.txt")),
    (56, include_str!("../../../data/viewsets/tammes-56.txt")),
    (64, include_str!("../../../data/viewsets/tammes-64.txt")),
    (80, include_str!("../../../data/viewsets/tammes-80.txt")),
    (96, include_str!("../../../data/viewsets/tammes-96.txt")),
    (112, include_str!("../../../data/viewsets/tammes-112.txt")),
    (128, include_str!("../../../data/viewsets/tammes-128.txt")),
    (144, include_str!("../../../data/viewsets/tammes-144.txt")),
    (160, include_str!("../../../data/viewsets/tammes-160.txt")),
    (180, include_str!("../../../data/viewsets/tammes-180.txt")),
    (200, include_str!("../../../data/viewsets/tammes-200.txt")),
    (270, include_str!("../../../data/viewsets/tammes-270.txt")),
    (360, include_str!("../../../data/viewsets/tammes-360.txt")),
    (432, include_str!("../../../data/viewsets/tammes-432.txt")),
    (492, include_str!("../../../data/viewsets/tammes-492.txt")),
];

/// The shipped sizes N, increasing.
pub fn shipped_sizes() -> Vec<usize> {
    SHIPPED_TAMMES.iter().map(|(n, _)| *n).collect()
}

/// The text of the shipped set named `tammes-N`, if any.
pub fn tammes_text(spec: &str) -> Option<&'static str> {
    let n: usize = spec.strip_prefix("tammes-")?.parse().ok()?;
    SHIPPED_TAMMES.iter().find(|(k, _)| *k == n).map(|(_, t)| *t)
}
