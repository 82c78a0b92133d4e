//! gzip of responses (docs/server-api.md, "Compression"): a response is sent gzip-compressed
//! (`Content-Encoding: gzip`, fastest level) when the request's `Accept-Encoding` allows gzip
//! (`gzip`, `x-gzip` or `*` with a q-value above 0), its body is at least [`MIN_GZIP_BYTES`] and
//! it is not an image (the PNG is compressed already). Every other response — no such header,
//! a small body, an image — goes out as it is. Responses that may be compressed carry
//! `Vary: Accept-Encoding` either way. The depth NPY (1 MiB of `<f4`, mostly background zeros)
//! is what gains: see the server figures in `docs/performance.md`.
//!
//! Every body of [`crate::api`] is produced whole before it is sent, so compressing it whole
//! changes no timing a client sees beyond the compression itself; bodies over
//! [`INLINE_LIMIT`] are compressed on the blocking pool.

use std::io::Write;

use axum::body::Body;
use axum::extract::Request;
use axum::http::header::{
    HeaderValue, ACCEPT_ENCODING, CONTENT_ENCODING, CONTENT_LENGTH, CONTENT_TYPE, VARY,
};
use axum::http::HeaderMap;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::error::ApiError;

/// Bodies shorter than this are sent as they are (gzip would save next to nothing).
pub const MIN_GZIP_BYTES: usize = 1024;

/// Bodies longer than this are compressed on the blocking pool rather than on the executor.
pub const INLINE_LIMIT: usize = 64 << 10;

/// Whether `Accept-Encoding` allows gzip: `gzip` / `x-gzip` with q > 0, or else `*` with q > 0.
pub fn accepts_gzip(headers: &HeaderMap) -> bool {
    let (mut gzip, mut star) = (None, None);
    for value in headers.get_all(ACCEPT_ENCODING) {
        let Ok(value) = value.to_str() else { continue };
        for item in value.split(',') {
            let mut parts = item.split(';');
            let coding = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let q = parts
                .find_map(|p| {
                    let p = p.trim();
                    p.strip_prefix("q=").or_else(|| p.strip_prefix("Q="))
                })
                .map_or(1.0, |q| q.trim().parse::<f64>().unwrap_or(0.0));
            match coding.as_str() {
                "gzip" | "x-gzip" => gzip = Some(q > 0.0),
                "*" => star = Some(q > 0.0),
                _ => {}
            }
        }
    }
    gzip.or(star).unwrap_or(false)
}

/// `data` gzip-compressed at the fastest level.
pub fn gzip_bytes(data: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut enc =
        flate2::write::GzEncoder::new(Vec::with_capacity(data.len() / 4 + 64), flate2::Compression::fast());
    enc.write_all(data)?;
    enc.finish()
}

/// Whether a response may be compressed: not already encoded, not an image.
fn compressible(res: &Response) -> bool {
    let h = res.headers();
    let image = h.get(CONTENT_TYPE).and_then(|v| v.to_str().ok()).is_some_and(|t| t.starts_with("image/"));
    !h.contains_key(CONTENT_ENCODING) && !image
}

/// The middleware of the router (see the module docs).
pub async fn gzip(req: Request, next: Next) -> Response {
    let wants = accepts_gzip(req.headers());
    let mut res = next.run(req).await;
    if !compressible(&res) {
        return res;
    }
    res.headers_mut().append(VARY, HeaderValue::from_static("accept-encoding"));
    if !wants {
        return res;
    }
    let (mut parts, body) = res.into_parts();
    let bytes = match axum::body::to_bytes(body, usize::MAX).await {
        Ok(b) => b,
        Err(e) => {
            return ApiError::Internal(format!("reading the response to compress it: {e}")).into_response()
        }
    };
    if bytes.len() < MIN_GZIP_BYTES {
        return Response::from_parts(parts, Body::from(bytes));
    }
    let packed = if bytes.len() <= INLINE_LIMIT {
        gzip_bytes(&bytes)
    } else {
        let b = bytes.clone();
        tokio::task::spawn_blocking(move || gzip_bytes(&b))
            .await
            .unwrap_or_else(|e| Err(std::io::Error::other(e.to_string())))
    };
    match packed {
        Ok(p) => {
            parts.headers.insert(CONTENT_ENCODING, HeaderValue::from_static("gzip"));
            parts.headers.remove(CONTENT_LENGTH);
            Response::from_parts(parts, Body::from(p))
        }
        // Writing into memory does not fail; should it, the body goes out as it is.
        Err(_) => Response::from_parts(parts, Body::from(bytes)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(values: &[&str]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for v in values {
            h.append(ACCEPT_ENCODING, HeaderValue::from_str(v).unwrap());
        }
        h
    }

    #[test]
    fn accept_encoding_allows_gzip_only_when_it_says_so() {
        for yes in [
            &["gzip"][..],
            &["gzip, deflate, br"],
            &["br;q=1.0, GZIP;q=0.5"],
            &["x-gzip"],
            &["*"],
            &["identity", "gzip"],
        ] {
            assert!(accepts_gzip(&headers(yes)), "{yes:?}");
        }
        for no in [
            &[][..],
            &["identity"],
            &["br, deflate"],
            &["gzip;q=0"],
            &["gzip;q=0.0, *"],
            &["*;q=0"],
            &["gzipx"],
        ] {
            assert!(!accepts_gzip(&headers(no)), "{no:?}");
        }
    }

    #[test]
    fn gzip_round_trips_and_shrinks_zeros() {
        use std::io::Read;
        let data: Vec<u8> = (0..100_000u32).map(|i| if i % 97 == 0 { (i % 251) as u8 } else { 0 }).collect();
        let packed = gzip_bytes(&data).unwrap();
        assert_eq!(&packed[..2], &[0x1f, 0x8b], "the gzip magic");
        assert!(packed.len() < data.len() / 10, "{} bytes", packed.len());
        let mut back = Vec::new();
        flate2::read::GzDecoder::new(&packed[..]).read_to_end(&mut back).unwrap();
        assert_eq!(back, data);
    }
}
