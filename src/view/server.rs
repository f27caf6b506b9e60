//! The viewer's HTTP server: GET requests on 127.0.0.1, parsed by `httparse` (hyper's
//! parser), each connection on a thread of its own within fixed bounds, so that what a
//! client sends cannot grow the server's memory or threads without limit:
//!
//! - at most [`MAX_CONNECTIONS`] at once (each thread's stack [`STACK_BYTES`]); one more
//!   is answered 503 and closed;
//! - a request's header within [`MAX_HEADER_BYTES`] and [`MAX_HEADERS`] lines, else 431,
//!   read within [`READ_TIMEOUT`] (an idle connection is closed after it), the response
//!   written within [`WRITE_TIMEOUT`];
//! - `Host`, and `Origin` where a request has one, must name 127.0.0.1, `localhost` or
//!   `[::1]` with the viewer's port, else 403: a web page the user visits cannot read the
//!   frames by pointing a host name of its own at 127.0.0.1 (DNS rebinding), the check
//!   Jupyter and Vite make.
//!
//! One request per connection (`Connection: close`), which is all the page makes.

use anyhow::{Context, Result};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Connections served at once.
pub const MAX_CONNECTIONS: usize = 512;
/// Each connection thread's stack: the handlers allocate on the heap.
pub const STACK_BYTES: usize = 256 * 1024;
/// A request's header, request line included.
pub const MAX_HEADER_BYTES: usize = 16 * 1024;
pub const MAX_HEADERS: usize = 64;
pub const READ_TIMEOUT: Duration = Duration::from_secs(5);
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

/// A GET request's path and query (without the `?`).
pub struct Request<'a> {
    pub path: &'a str,
    pub query: &'a str,
}

/// An HTTP response.
pub struct Response {
    pub status: u16,
    pub content_type: &'static str,
    pub body: Vec<u8>,
}

impl Response {
    pub fn ok(content_type: &'static str, body: Vec<u8>) -> Self {
        Self { status: 200, content_type, body }
    }

    pub fn error(status: u16, message: &str) -> Self {
        Self { status, content_type: "text/plain; charset=utf-8", body: message.as_bytes().to_vec() }
    }

    fn send(self, stream: &mut TcpStream) -> std::io::Result<()> {
        let reason = match self.status {
            200 => "OK",
            400 => "Bad Request",
            403 => "Forbidden",
            404 => "Not Found",
            405 => "Method Not Allowed",
            409 => "Conflict",
            431 => "Request Header Fields Too Large",
            503 => "Service Unavailable",
            _ => "Internal Server Error",
        };
        write!(
            stream,
            "HTTP/1.1 {} {reason}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
            self.status,
            self.content_type,
            self.body.len()
        )?;
        stream.write_all(&self.body)?;
        stream.flush()
    }
}

/// Binds 127.0.0.1:`port` (0: any free port), saying so plainly when the port is taken.
pub fn bind(port: u16) -> Result<TcpListener> {
    TcpListener::bind(("127.0.0.1", port)).map_err(|e| match e.kind() {
        std::io::ErrorKind::AddrInUse => anyhow::anyhow!(
            "port {port} is taken (another logsh view, or another server); pass --port 0 for any free port, \
             or another port"
        ),
        _ => anyhow::Error::new(e).context(format!("cannot listen on 127.0.0.1:{port}")),
    })
}

/// Serves `listener` until the process ends, answering each request with `handle`.
pub fn serve(listener: TcpListener, handle: impl Fn(&Request) -> Response + Send + Sync + 'static) -> Result<()> {
    let port = listener.local_addr()?.port();
    let hosts = Arc::new(["127.0.0.1", "localhost", "[::1]"].map(|h| format!("{h}:{port}")));
    let handle = Arc::new(handle);
    let open = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        if open.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
            open.fetch_sub(1, Ordering::SeqCst);
            let _ = stream.set_write_timeout(Some(Duration::from_millis(100)));
            let _ = Response::error(503, "too many connections").send(&mut stream);
            continue;
        }
        let (handle, hosts, served) = (handle.clone(), hosts.clone(), open.clone());
        let spawned = std::thread::Builder::new().stack_size(STACK_BYTES).spawn(move || {
            // A client that leaves, or sends nothing in time, is its own business.
            use std::io::ErrorKind::*;
            if let Err(e) = answer(stream, hosts.as_slice(), handle.as_ref()) {
                if !matches!(e.kind(), WouldBlock | TimedOut | UnexpectedEof | ConnectionReset | BrokenPipe) {
                    eprintln!("view: {e}");
                }
            }
            served.fetch_sub(1, Ordering::SeqCst);
        });
        if spawned.is_err() {
            open.fetch_sub(1, Ordering::SeqCst);
        }
    }
    Ok(())
}

fn answer(
    mut stream: TcpStream,
    hosts: &[String],
    handle: &(impl Fn(&Request) -> Response + ?Sized),
) -> std::io::Result<()> {
    stream.set_read_timeout(Some(READ_TIMEOUT))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let Some(head) = read_head(&mut stream)? else {
        Response::error(431, "the request's header is too large").send(&mut stream)?;
        // Closing with the rest of the header unread would reset the connection before
        // the client reads the answer: a little more is read and dropped first.
        stream.shutdown(std::net::Shutdown::Write)?;
        stream.set_read_timeout(Some(Duration::from_millis(200)))?;
        let _ = std::io::copy(&mut (&mut stream).take(1 << 20), &mut std::io::sink());
        return Ok(());
    };
    let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
    let mut request = httparse::Request::new(&mut headers);
    let response = match request.parse(&head) {
        Err(httparse::Error::TooManyHeaders) => Response::error(431, "the request has too many header lines"),
        Err(_) | Ok(httparse::Status::Partial) => Response::error(400, "not an HTTP request"),
        Ok(httparse::Status::Complete(_)) => {
            let header = |name: &str| {
                request.headers.iter().find(|h| h.name.eq_ignore_ascii_case(name)).map(|h| h.value.to_ascii_lowercase())
            };
            let named = |value: &[u8]| hosts.iter().any(|h| h.as_bytes() == value);
            let host_ok = header("host").is_some_and(|h| named(&h));
            let origin_ok = header("origin").is_none_or(|o| o.strip_prefix(b"http://".as_slice()).is_some_and(&named));
            if !host_ok || !origin_ok {
                Response::error(403, "the viewer answers requests to 127.0.0.1, localhost or [::1] at its port only")
            } else if request.method != Some("GET") {
                Response::error(405, "only GET is served")
            } else {
                let target = request.path.unwrap_or("/");
                let (path, query) = target.split_once('?').unwrap_or((target, ""));
                handle(&Request { path, query })
            }
        }
    };
    response.send(&mut stream)
}

/// The request's header up to and including its blank line; `None` when it passes
/// [`MAX_HEADER_BYTES`].
fn read_head(stream: &mut TcpStream) -> std::io::Result<Option<Vec<u8>>> {
    let mut head = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        let read = stream.read(&mut chunk)?;
        if read == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        let searched = head.len().saturating_sub(3);
        head.extend_from_slice(&chunk[..read]);
        if let Some(end) = head[searched..].windows(4).position(|w| w == b"\r\n\r\n") {
            head.truncate(searched + end + 4);
            return Ok(Some(head));
        }
        if head.len() > MAX_HEADER_BYTES {
            return Ok(None);
        }
    }
}

/// The address the page is served at.
pub fn address(listener: &TcpListener) -> Result<String> {
    Ok(format!("http://{}/", listener.local_addr().context("the listening socket")?))
}
