//! View spaces (SPEC §5): which camera poses a planner may request.
//!
//! A view space is a rule file in the reference implementation's format:
//!
//! ```json
//! { "name": "hemi", "description": "...", "pose_format": "camera_lookat_roll", "atol": 0.0001,
//!   "structured_rule": { "logic": "and", "rules": [
//!       {"field": "camera_radius", "op": ">=", "value": 1.0},
//!       {"field": "camera_z", "op": ">=", "value": 0.0} ] },
//!   "blocklist": { "poses": [[cx, cy, cz, lx, ly, lz, roll], ...] } }
//! ```
//!
//! Fields: `camera_x/y/z`, `lookat_x/y/z`, `roll_rad`, `camera_radius`; ops `>=`, `>`, `<=`,
//! `<`, `==`, `!=`; logic `and` / `or` (default `and`). As an extension, an item of `rules` may
//! itself be a group `{"logic": ..., "rules": [...]}` (nesting to any depth). `structured_rule`
//! and `blocklist` are optional (a file without either allows every pose); `atol` defaults to
//! 1e-4 and `pose_format` must be `camera_lookat_roll` when given.
//!
//! Tolerance (`atol`): `==` passes when |v − t| ≤ atol, `!=` when |v − t| > atol, and a pose is
//! on the blocklist when every one of its 7 numbers is within atol of a listed pose — exactly as
//! the reference implementation (`benchmark/api_feasibility.py`). For the inequalities the
//! reference compares exactly; that is the default here too ([`InequalityTolerance::Exact`]),
//! because SPEC defaults follow the reference so episodes are comparable with the paper. The
//! alternative [`InequalityTolerance::Lenient`] reads the tolerance as absorbing round-off on
//! both sides of a boundary: `>=`/`>` pass when v ≥ t − atol / v > t − atol, `<=`/`<` when
//! v ≤ t + atol / v < t + atol (so a pose computed as z = −1e-17 on the z = 0 boundary of `hemi`
//! is accepted). The shipped tammes sets have no coordinate within 1e-3 of a boundary, so their
//! feasible counts are the same under both modes.
//!
//! `camera_radius` is computed like the reference (the norm of the camera centre in single
//! precision: components and result rounded to f32), which matters only within ~1e-7 of a
//! radius threshold.
//!
//! Malformed files are rejected with the file and the JSON path of the offending item, e.g.
//! `hemi.json: structured_rule.rules[1].op: unknown op "=>" (expected one of >=, >, <=, <, ==, !=)`.

use std::fmt;
use std::path::Path;

use objview_geom::Pose;
use serde_json::{Map, Value};

use crate::error::ViewsError;

/// A pose field a rule can test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// Camera centre x.
    CameraX,
    /// Camera centre y.
    CameraY,
    /// Camera centre z.
    CameraZ,
    /// Look-at point x.
    LookatX,
    /// Look-at point y.
    LookatY,
    /// Look-at point z.
    LookatZ,
    /// Roll about the viewing axis, radians.
    RollRad,
    /// Distance of the camera centre from the origin.
    CameraRadius,
}

const FIELDS: &[(&str, Field)] = &[
    ("camera_x", Field::CameraX),
    ("camera_y", Field::CameraY),
    ("camera_z", Field::CameraZ),
    ("lookat_x", Field::LookatX),
    ("lookat_y", Field::LookatY),
    ("lookat_z", Field::LookatZ),
    ("roll_rad", Field::RollRad),
    ("camera_radius", Field::CameraRadius),
];

impl Field {
    /// The name used in rule files.
    pub fn name(self) -> &'static str {
        FIELDS.iter().find(|(_, f)| *f == self).map(|(n, _)| *n).expect("every field is listed")
    }

    /// The field's value for `pose`.
    pub fn value(self, pose: &Pose) -> f64 {
        let (c, l) = (pose.center, pose.look_at);
        match self {
            Field::CameraX => c[0],
            Field::CameraY => c[1],
            Field::CameraZ => c[2],
            Field::LookatX => l[0],
            Field::LookatY => l[1],
            Field::LookatZ => l[2],
            Field::RollRad => pose.roll,
            Field::CameraRadius => {
                // Single precision, as the reference implementation (float32 norm).
                let f = [c[0] as f32 as f64, c[1] as f32 as f64, c[2] as f32 as f64];
                ((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt() as f32) as f64
            }
        }
    }
}

/// A comparison operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// `>=`
    Ge,
    /// `>`
    Gt,
    /// `<=`
    Le,
    /// `<`
    Lt,
    /// `==` (within atol)
    Eq,
    /// `!=` (farther than atol)
    Ne,
}

const OPS: &[(&str, Op)] =
    &[(">=", Op::Ge), (">", Op::Gt), ("<=", Op::Le), ("<", Op::Lt), ("==", Op::Eq), ("!=", Op::Ne)];

impl Op {
    /// The operator's spelling in rule files.
    pub fn symbol(self) -> &'static str {
        OPS.iter().find(|(_, o)| *o == self).map(|(s, _)| *s).expect("every op is listed")
    }

    /// The spelling of the negation (used to explain a violated rule).
    fn negated_symbol(self) -> &'static str {
        match self {
            Op::Ge => "<",
            Op::Gt => "<=",
            Op::Le => ">",
            Op::Lt => ">=",
            Op::Eq => "!=",
            Op::Ne => "==",
        }
    }
}

/// Whether `atol` also relaxes `>=`, `>`, `<=`, `<` (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InequalityTolerance {
    /// Exact comparisons, as the reference implementation (default).
    #[default]
    Exact,
    /// Inequalities relaxed by atol towards passing.
    Lenient,
}

/// AND / OR.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Logic {
    /// Every rule must hold.
    And,
    /// At least one rule must hold.
    Or,
}

/// A rule: a comparison or a group.
#[derive(Debug, Clone, PartialEq)]
pub enum Rule {
    /// `field op value`.
    Cmp {
        /// Tested field.
        field: Field,
        /// Operator.
        op: Op,
        /// Threshold (finite).
        value: f64,
    },
    /// A nested group.
    Group {
        /// How the members combine.
        logic: Logic,
        /// Members (non-empty).
        rules: Vec<Rule>,
    },
}

/// A view space: a named feasibility rule set.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSpace {
    /// `name` from the file, else the file stem.
    pub name: String,
    /// `description` from the file (empty when absent).
    pub description: String,
    /// Tolerance of `==`, `!=` and the blocklist (and of inequalities when lenient).
    pub atol: f64,
    /// The structured rule; `None` allows every pose (up to the blocklist).
    pub rule: Option<Rule>,
    /// Poses removed from the space.
    pub blocklist: Vec<Pose>,
    /// How atol applies to inequalities.
    pub inequality_tolerance: InequalityTolerance,
}

/// The built-in spaces: name and verbatim copy of the official rule file.
pub const BUILTIN_SPACES: &[(&str, &str)] = &[
    ("whole", include_str!("../../../data/feasibility/whole.json")),
    ("hemi", include_str!("../../../data/feasibility/hemi.json")),
    ("quarter", include_str!("../../../data/feasibility/quarter.json")),
    ("eighth", include_str!("../../../data/feasibility/eighth.json")),
];

fn rule_err(origin: &str, json_path: &str, reason: impl Into<String>) -> ViewsError {
    ViewsError::Rule { path: origin.to_string(), json_path: json_path.to_string(), reason: reason.into() }
}

fn json_type(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

fn check_keys(
    origin: &str,
    path: &str,
    obj: &Map<String, Value>,
    allowed: &[&str],
) -> Result<(), ViewsError> {
    for k in obj.keys() {
        if !allowed.contains(&k.as_str()) {
            let item = if path.is_empty() { k.clone() } else { format!("{path}.{k}") };
            return Err(rule_err(
                origin,
                &item,
                format!("unknown field {k:?} (expected one of {})", allowed.join(", ")),
            ));
        }
    }
    Ok(())
}

fn finite_number(origin: &str, path: &str, v: &Value) -> Result<f64, ViewsError> {
    let x = v
        .as_f64()
        .ok_or_else(|| rule_err(origin, path, format!("must be a number, found {}", json_type(v))))?;
    if !x.is_finite() {
        return Err(rule_err(origin, path, format!("must be finite, found {x}")));
    }
    Ok(x)
}

fn parse_group(origin: &str, path: &str, v: &Value) -> Result<Rule, ViewsError> {
    let obj = v.as_object().ok_or_else(|| {
        rule_err(origin, path, format!("a rule group must be an object, found {}", json_type(v)))
    })?;
    check_keys(origin, path, obj, &["logic", "rules"])?;
    let logic = match obj.get("logic") {
        None => Logic::And,
        Some(Value::String(s)) if s == "and" => Logic::And,
        Some(Value::String(s)) if s == "or" => Logic::Or,
        Some(other) => {
            return Err(rule_err(
                origin,
                &format!("{path}.logic"),
                format!("unknown logic {other} (expected \"and\" or \"or\")"),
            ))
        }
    };
    let rules_path = format!("{path}.rules");
    let items = match obj.get("rules") {
        None => return Err(rule_err(origin, &rules_path, "missing (a non-empty list of rules)")),
        Some(Value::Array(a)) => a,
        Some(other) => {
            return Err(rule_err(origin, &rules_path, format!("must be a list, found {}", json_type(other))))
        }
    };
    if items.is_empty() {
        return Err(rule_err(origin, &rules_path, "empty list (at least one rule is needed)"));
    }
    let rules = items
        .iter()
        .enumerate()
        .map(|(i, item)| parse_item(origin, &format!("{rules_path}[{i}]"), item))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Rule::Group { logic, rules })
}

fn parse_item(origin: &str, path: &str, v: &Value) -> Result<Rule, ViewsError> {
    let obj = v
        .as_object()
        .ok_or_else(|| rule_err(origin, path, format!("a rule must be an object, found {}", json_type(v))))?;
    if obj.contains_key("rules") || obj.contains_key("logic") {
        return parse_group(origin, path, v);
    }
    check_keys(origin, path, obj, &["field", "op", "value"])?;
    let field = match obj.get("field") {
        None => return Err(rule_err(origin, &format!("{path}.field"), "missing")),
        Some(Value::String(s)) => FIELDS.iter().find(|(n, _)| n == s).map(|(_, f)| *f).ok_or_else(|| {
            rule_err(
                origin,
                &format!("{path}.field"),
                format!(
                    "unknown field {s:?} (expected one of {})",
                    FIELDS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                ),
            )
        })?,
        Some(other) => {
            return Err(rule_err(
                origin,
                &format!("{path}.field"),
                format!("must be a string, found {}", json_type(other)),
            ))
        }
    };
    let op = match obj.get("op") {
        None => return Err(rule_err(origin, &format!("{path}.op"), "missing")),
        Some(Value::String(s)) => OPS.iter().find(|(n, _)| n == s).map(|(_, o)| *o).ok_or_else(|| {
            rule_err(
                origin,
                &format!("{path}.op"),
                format!("unknown op {s:?} (expected one of >=, >, <=, <, ==, !=)"),
            )
        })?,
        Some(other) => {
            return Err(rule_err(
                origin,
                &format!("{path}.op"),
                format!("must be a string, found {}", json_type(other)),
            ))
        }
    };
    let value = match obj.get("value") {
        None => return Err(rule_err(origin, &format!("{path}.value"), "missing")),
        Some(v) => finite_number(origin, &format!("{path}.value"), v)?,
    };
    Ok(Rule::Cmp { field, op, value })
}

fn parse_blocklist(origin: &str, v: &Value) -> Result<Vec<Pose>, ViewsError> {
    let obj = v
        .as_object()
        .ok_or_else(|| rule_err(origin, "blocklist", format!("must be an object, found {}", json_type(v))))?;
    check_keys(origin, "blocklist", obj, &["poses"])?;
    let Some(poses) = obj.get("poses") else {
        return Ok(Vec::new());
    };
    let arr = poses.as_array().ok_or_else(|| {
        rule_err(origin, "blocklist.poses", format!("must be a list, found {}", json_type(poses)))
    })?;
    let mut out = Vec::with_capacity(arr.len());
    for (i, p) in arr.iter().enumerate() {
        let path = format!("blocklist.poses[{i}]");
        let nums = p.as_array().filter(|a| a.len() == 7).ok_or_else(|| {
            rule_err(origin, &path, "must be a list of 7 numbers [cx, cy, cz, lx, ly, lz, roll]")
        })?;
        let mut a = [0.0; 7];
        for (k, x) in nums.iter().enumerate() {
            a[k] = finite_number(origin, &format!("{path}[{k}]"), x)?;
        }
        out.push(Pose::from_array(a).expect("all finite"));
    }
    Ok(out)
}

/// Outcome of evaluating a rule: `Ok(())` or the reason it failed.
fn eval(
    rule: &Rule,
    pose: &Pose,
    atol: f64,
    tol: InequalityTolerance,
    label: &str,
    want_reason: bool,
) -> Result<(), Option<String>> {
    match rule {
        Rule::Cmp { field, op, value } => {
            let v = field.value(pose);
            let slack = match tol {
                InequalityTolerance::Exact => 0.0,
                InequalityTolerance::Lenient => atol,
            };
            let ok = match op {
                Op::Ge => v >= value - slack,
                Op::Gt => v > value - slack,
                Op::Le => v <= value + slack,
                Op::Lt => v < value + slack,
                Op::Eq => (v - value).abs() <= atol,
                Op::Ne => (v - value).abs() > atol,
            };
            if ok {
                Ok(())
            } else if want_reason {
                let tol_note = match op {
                    Op::Eq | Op::Ne => format!(" (atol {atol})"),
                    _ => String::new(),
                };
                Err(Some(format!(
                    "{} = {v} {} {value}{tol_note} (rule {label})",
                    field.name(),
                    op.negated_symbol()
                )))
            } else {
                Err(None)
            }
        }
        Rule::Group { logic, rules } => {
            let sub = |i: usize| {
                if label.is_empty() {
                    format!("{}", i + 1)
                } else {
                    format!("{label}.{}", i + 1)
                }
            };
            match logic {
                Logic::And => {
                    for (i, r) in rules.iter().enumerate() {
                        eval(r, pose, atol, tol, &sub(i), want_reason)?;
                    }
                    Ok(())
                }
                Logic::Or => {
                    let mut reasons = Vec::new();
                    for (i, r) in rules.iter().enumerate() {
                        match eval(r, pose, atol, tol, &sub(i), want_reason) {
                            Ok(()) => return Ok(()),
                            Err(reason) => reasons.extend(reason),
                        }
                    }
                    if want_reason {
                        Err(Some(format!("none of the alternatives holds: {}", reasons.join("; "))))
                    } else {
                        Err(None)
                    }
                }
            }
        }
    }
}

impl ViewSpace {
    /// Parses rule-file text; `origin` names the source in error messages (a path, or
    /// `builtin:NAME`), and its stem is the default name.
    pub fn parse(origin: &str, text: &str) -> Result<ViewSpace, ViewsError> {
        let root: Value = serde_json::from_str(text)
            .map_err(|e| ViewsError::RuleJson { path: origin.to_string(), reason: e.to_string() })?;
        let obj = root.as_object().ok_or_else(|| {
            rule_err(origin, "$", format!("must be a JSON object, found {}", json_type(&root)))
        })?;
        check_keys(
            origin,
            "",
            obj,
            &["name", "description", "pose_format", "atol", "structured_rule", "blocklist"],
        )?;
        let string_of = |key: &str| -> Result<Option<String>, ViewsError> {
            match obj.get(key) {
                None => Ok(None),
                Some(Value::String(s)) => Ok(Some(s.clone())),
                Some(other) => {
                    Err(rule_err(origin, key, format!("must be a string, found {}", json_type(other))))
                }
            }
        };
        let stem = Path::new(origin.trim_start_matches("builtin:"))
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| origin.to_string());
        let name = string_of("name")?.unwrap_or(stem);
        let description = string_of("description")?.unwrap_or_default();
        if let Some(fmt) = string_of("pose_format")? {
            if fmt != "camera_lookat_roll" {
                return Err(rule_err(
                    origin,
                    "pose_format",
                    format!("unsupported pose format {fmt:?} (expected \"camera_lookat_roll\")"),
                ));
            }
        }
        let atol = match obj.get("atol") {
            None => 1e-4,
            Some(v) => {
                let a = finite_number(origin, "atol", v)?;
                if a < 0.0 {
                    return Err(rule_err(origin, "atol", format!("must be >= 0, found {a}")));
                }
                a
            }
        };
        let rule = match obj.get("structured_rule") {
            None => None,
            Some(v) => Some(parse_group(origin, "structured_rule", v)?),
        };
        let blocklist = match obj.get("blocklist") {
            None => Vec::new(),
            Some(v) => parse_blocklist(origin, v)?,
        };
        Ok(ViewSpace {
            name,
            description,
            atol,
            rule,
            blocklist,
            inequality_tolerance: InequalityTolerance::default(),
        })
    }

    /// Loads a rule file.
    pub fn load(path: &Path) -> Result<ViewSpace, ViewsError> {
        let text = objview_geom::fsutil::read_text(path).map_err(|source| ViewsError::Io {
            path: path.to_path_buf(),
            op: "read",
            source,
        })?;
        ViewSpace::parse(&path.display().to_string(), &text)
    }

    /// A built-in space (`whole`, `hemi`, `quarter`, `eighth`), if `name` is one.
    pub fn builtin(name: &str) -> Option<ViewSpace> {
        BUILTIN_SPACES.iter().find(|(n, _)| *n == name).map(|(n, text)| {
            ViewSpace::parse(&format!("builtin:{n}.json"), text).expect("built-in rule files parse")
        })
    }

    /// A built-in space name, or a rule-file path.
    pub fn resolve(name_or_path: &str) -> Result<ViewSpace, ViewsError> {
        if let Some(vs) = ViewSpace::builtin(name_or_path) {
            return Ok(vs);
        }
        let path = Path::new(name_or_path);
        if path.is_file() {
            return ViewSpace::load(path);
        }
        Err(ViewsError::UnknownViewSpace { spec: name_or_path.to_string() })
    }

    /// The same space with another inequality tolerance mode.
    pub fn with_inequality_tolerance(mut self, tol: InequalityTolerance) -> ViewSpace {
        self.inequality_tolerance = tol;
        self
    }

    fn blocked(&self, pose: &Pose) -> Option<usize> {
        let (a, atol) = (pose.to_array(), self.atol);
        self.blocklist.iter().position(|b| b.to_array().iter().zip(&a).all(|(x, y)| (x - y).abs() <= atol))
    }

    /// Whether `pose` is in the space. Non-finite poses are never feasible.
    pub fn is_feasible(&self, pose: &Pose) -> bool {
        if !pose.to_array().iter().all(|v| v.is_finite()) {
            return false;
        }
        let ok = match &self.rule {
            None => true,
            Some(r) => eval(r, pose, self.atol, self.inequality_tolerance, "", false).is_ok(),
        };
        ok && self.blocked(pose).is_none()
    }

    /// [`ViewSpace::is_feasible`] for every pose, in order.
    pub fn feasible_mask(&self, poses: &[Pose]) -> Vec<bool> {
        poses.iter().map(|p| self.is_feasible(p)).collect()
    }

    /// `None` when `pose` is feasible, else the first violated rule, e.g.
    /// `camera_z = -0.3 < 0 (rule 2)` (rules numbered from 1, nested ones as `2.1`).
    pub fn explain(&self, pose: &Pose) -> Option<String> {
        if !pose.to_array().iter().all(|v| v.is_finite()) {
            return Some("pose has a non-finite number".to_string());
        }
        if let Some(r) = &self.rule {
            if let Err(reason) = eval(r, pose, self.atol, self.inequality_tolerance, "", true) {
                return Some(reason.unwrap_or_else(|| "structured rule not satisfied".into()));
            }
        }
        self.blocked(pose).map(|i| format!("pose is on the blocklist (entry {})", i + 1))
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rule::Cmp { field, op, value } => write!(f, "{} {} {value}", field.name(), op.symbol()),
            Rule::Group { logic, rules } => {
                let sep = match logic {
                    Logic::And => " and ",
                    Logic::Or => " or ",
                };
                write!(f, "(")?;
                for (i, r) in rules.iter().enumerate() {
                    if i > 0 {
                        write!(f, "{sep}")?;
                    }
                    write!(f, "{r}")?;
                }
                write!(f, ")")
            }
        }
    }
}
