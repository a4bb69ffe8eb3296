//! A minimal blocking HTTP/1.0 GET, for `mousepose status` and the tests: one request per
//! connection, the answer read to its end within a time limit.

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

/// The largest answer read (the status is a few kilobytes, a picture well under this).
const MAX_ANSWER: u64 = 32 << 20;

/// An HTTP answer.
#[derive(Debug)]
pub struct Answer {
    pub status: u16,
    pub content_type: Option<String>,
    pub body: Vec<u8>,
}

/// Why a request failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot reach http://{address} (is `mousepose run` running with [http] there?)")]
    Connect {
        address: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("no whole answer from http://{address}{path}")]
    Read {
        address: SocketAddr,
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("http://{address}{path} did not answer in HTTP")]
    Malformed { address: SocketAddr, path: String },
}

/// Sends `GET path` (with the bearer `token`, if any) and reads the answer.
///
/// # Errors
/// The address cannot be reached within `timeout`, or the answer is not HTTP.
pub fn get(address: SocketAddr, path: &str, token: Option<&str>, timeout: Duration) -> Result<Answer, ClientError> {
    let read_error = |source| ClientError::Read {
        address,
        path: path.to_owned(),
        source,
    };
    let mut stream =
        TcpStream::connect_timeout(&address, timeout).map_err(|source| ClientError::Connect { address, source })?;
    stream.set_read_timeout(Some(timeout)).map_err(read_error)?;
    stream.set_write_timeout(Some(timeout)).map_err(read_error)?;
    let auth = token.map_or_else(String::new, |t| format!("Authorization: Bearer {t}\r\n"));
    write!(stream, "GET {path} HTTP/1.0\r\nHost: {address}\r\n{auth}\r\n").map_err(read_error)?;
    let mut raw = Vec::new();
    stream.take(MAX_ANSWER).read_to_end(&mut raw).map_err(read_error)?;
    parse(&raw).ok_or_else(|| ClientError::Malformed {
        address,
        path: path.to_owned(),
    })
}

fn parse(raw: &[u8]) -> Option<Answer> {
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&raw[..split]).ok()?;
    let mut lines = head.split("\r\n");
    let status = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let content_type = lines.find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.eq_ignore_ascii_case("content-type").then(|| v.trim().to_owned())
    });
    Some(Answer {
        status,
        content_type,
        body: raw[split + 4..].to_vec(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_answer_is_split_into_status_type_and_body() {
        let a =
            parse(b"HTTP/1.0 401 Unauthorized\r\ncontent-type: text/plain\r\nx: y\r\n\r\nno\r\n\r\n").expect("parsed");
        assert_eq!(a.status, 401);
        assert_eq!(a.content_type.as_deref(), Some("text/plain"));
        assert_eq!(a.body, b"no\r\n\r\n");
        assert!(parse(b"garbage").is_none());
    }
}
