//! Shipped data built into the binary with `include_str!`: the `tammes-N` view sets of
//! `data/viewsets/` (SPEC §3), so no data files are needed at run time.

/// Every shipped `tammes-N` set: N and the file text.
pub const SHIPPED_TAMMES: &[(usize, &str)] = &[
    (128, include_str!("../../../data/viewsets/tammes-128.txt")),
    (360, include_str!("../../../data/viewsets/tammes-360.txt")),
];

/// The text of the shipped set named `tammes-N`, if any.
pub fn tammes_text(spec: &str) -> Option<&'static str> {
    let n: usize = spec.strip_prefix("tammes-")?.parse().ok()?;
    SHIPPED_TAMMES.iter().find(|(k, _)| *k == n).map(|(_, t)| *t)
}
