//! Bearer tokens (`--tokens FILE`: one token per line, `#` comments, an optional name after the
//! token). With tokens, every `/v1/` route except `/v1/health` needs `Authorization: Bearer
//! <token>`, and episodes belong to the token that created them. Owners are stored as a hash of
//! the token, never the token itself.

use axum::http::request::Parts;
use std::collections::HashMap;
use std::path::Path;

use crate::error::{ApiError, ServerError};

/// The accepted tokens and their names.
#[derive(Debug, Clone, Default)]
pub struct Tokens {
    names: HashMap<String, String>,
}

impl Tokens {
    /// Parses a tokens file's text; `what` names it in errors.
    pub fn parse(text: &str, what: &str) -> Result<Tokens, ServerError> {
        let mut names = HashMap::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let mut parts = line.splitn(2, char::is_whitespace);
            let token = parts.next().unwrap_or_default().to_string();
            let name = parts.next().unwrap_or("").trim().to_string();
            if names.insert(token, name).is_some() {
                return Err(ServerError::Tokens {
                    path: what.to_string(),
                    reason: format!("line {}: a token listed twice", i + 1),
                });
            }
        }
        if names.is_empty() {
            return Err(ServerError::Tokens { path: what.to_string(), reason: "no tokens".into() });
        }
        Ok(Tokens { names })
    }

    /// Reads a tokens file.
    pub fn load(path: &Path) -> Result<Tokens, ServerError> {
        let text = objview_geom::fsutil::read_text(path)
            .map_err(|e| ServerError::Tokens { path: path.display().to_string(), reason: e.to_string() })?;
        Tokens::parse(&text, &path.display().to_string())
    }

    /// Whether `token` is accepted.
    pub fn contains(&self, token: &str) -> bool {
        self.names.contains_key(token)
    }

    /// How many tokens there are.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }
}

/// The owner id of a token: `t-` and its 64-bit FNV-1a hash in hex.
pub fn owner_id(token: &str) -> String {
    let mut h = objview_geom::hash::Fnv::default();
    h.eat(token.as_bytes());
    format!("t-{:016x}", h.0)
}

/// Who is calling: the owner id of their token (empty on a server without tokens). Extracting
/// it fails with 401 `unauthorized` when the server has tokens and the request has no known one.
#[derive(Debug, Clone)]
pub struct Caller {
    /// The token's owner name (episodes belong to it).
    pub owner: String,
}

impl Caller {
    /// The caller of a request with headers `parts` on a server accepting `tokens` (none: every
    /// caller is anonymous). Fails with 401 `unauthorized` when the server has tokens and the
    /// request has no known one. The request extractor (`FromRequestParts`) is implemented
    /// where the server state lives (`state.rs`) and calls this.
    pub fn from_parts(parts: &Parts, tokens: Option<&Tokens>) -> Result<Caller, ApiError> {
        let Some(tokens) = tokens else {
            return Ok(Caller { owner: String::new() });
        };
        let header = parts
            .headers
            .get(axum::http::header::AUTHORIZATION)
            .ok_or_else(|| ApiError::Unauthorized("missing `Authorization: Bearer <token>` header".into()))?;
        let token =
            header.to_str().ok().and_then(|h| h.strip_prefix("Bearer ")).map(str::trim).ok_or_else(|| {
                ApiError::Unauthorized("the Authorization header must be `Bearer <token>`".into())
            })?;
        if !tokens.contains(token) {
            return Err(ApiError::Unauthorized("unknown token".into()));
        }
        Ok(Caller { owner: owner_id(token) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_files_parse_with_comments_and_names() {
        let t = Tokens::parse("# team\nabc alice\n\n  def   bob # second\nghi\n", "t.txt").unwrap();
        assert_eq!(t.len(), 3);
        assert!(t.contains("abc") && t.contains("def") && t.contains("ghi"));
        assert!(!t.contains("alice") && !t.contains("#"));
        assert!(Tokens::parse("# nothing\n\n", "t.txt").unwrap_err().to_string().contains("no tokens"));
        assert!(Tokens::parse("abc\nabc x\n", "t.txt").unwrap_err().to_string().contains("line 2"));
    }

    #[test]
    fn owners_are_hashes_of_tokens() {
        assert_eq!(owner_id("abc"), owner_id("abc"));
        assert_ne!(owner_id("abc"), owner_id("abd"));
        assert!(owner_id("secret").starts_with("t-") && !owner_id("secret").contains("secret"));
    }
}
