//! An XML-RPC server on `tiny_http`: every request is answered on its own thread, so a
//! blocking call (a MoveJ that waits for the motion) never holds up another (a StopMotion
//! on a second connection). Keep-alive and one connection per call both work, as
//! Python's `xmlrpc.client` uses either.

use super::value::{Fault, Value, parse_call, response_to_xml};
use std::io::{self, Read};
use std::net::SocketAddr;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use tiny_http::{Header, Method, Request, Response, Server};

/// Fault codes of the de-facto XML-RPC convention (as Python's server uses them).
const FAULT_PARSE: i32 = -32700;
const FAULT_INTERNAL: i32 = -32603;
/// Requests larger than this are refused; a controller call is a few hundred bytes.
const MAX_BODY: usize = 1 << 20;

/// Answers calls. Called from many threads at once.
pub trait Handler: Send + Sync + 'static {
    /// The reply to `method(params)`, or a fault (for an unknown method, say).
    fn call(&self, method: &str, params: Vec<Value>) -> Result<Value, Fault>;
}

/// A running server; stops on [`XmlRpcServer::shutdown`] or drop.
pub struct XmlRpcServer {
    server: Arc<Server>,
    local_addr: SocketAddr,
    stopping: Arc<AtomicBool>,
    dispatcher: Option<JoinHandle<()>>,
}

impl XmlRpcServer {
    /// Listens on `bind` (port 0 for any free port) and serves `handler` at `/RPC2` (and
    /// `/`, as Python's own server does).
    pub fn spawn(bind: SocketAddr, handler: Arc<dyn Handler>) -> io::Result<XmlRpcServer> {
        let server = Server::http(bind).map_err(|e| io::Error::other(format!("{bind}: {e}")))?;
        let local_addr = server
            .server_addr()
            .to_ip()
            .ok_or_else(|| io::Error::other("XML-RPC server has no IP address"))?;
        let server = Arc::new(server);
        let stopping = Arc::new(AtomicBool::new(false));
        let dispatcher = {
            let server = Arc::clone(&server);
            let stopping = Arc::clone(&stopping);
            std::thread::Builder::new()
                .name(format!("xmlrpc-{}", local_addr.port()))
                .spawn(move || dispatch(&server, &stopping, handler))?
        };
        Ok(XmlRpcServer {
            server,
            local_addr,
            stopping,
            dispatcher: Some(dispatcher),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Stops taking requests. Calls already running finish on their own threads.
    pub fn shutdown(&mut self) {
        self.stopping.store(true, Ordering::SeqCst);
        self.server.unblock();
        if let Some(dispatcher) = self.dispatcher.take() {
            let _ = dispatcher.join();
        }
    }
}

impl Drop for XmlRpcServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn dispatch(server: &Server, stopping: &AtomicBool, handler: Arc<dyn Handler>) {
    while !stopping.load(Ordering::SeqCst) {
        let Ok(request) = server.recv() else {
            continue; // unblocked (shutdown) or a transient accept error
        };
        let handler = Arc::clone(&handler);
        let spawned = std::thread::Builder::new()
            .name("xmlrpc-call".into())
            .spawn(move || answer(request, handler.as_ref()));
        if let Err(e) = spawned {
            tracing::warn!("XML-RPC server: cannot start a thread for a request: {e}");
        }
    }
}

fn text_xml() -> Header {
    Header::from_bytes("Content-Type", "text/xml").expect("a valid header")
}

fn plain(status: u16, text: &str) -> Response<io::Cursor<Vec<u8>>> {
    Response::from_string(text).with_status_code(status)
}

fn answer(mut request: Request, handler: &dyn Handler) {
    let path = request.url().split('?').next().unwrap_or("");
    let response = if *request.method() != Method::Post {
        plain(405, "XML-RPC takes POST\n")
    } else if path != "/RPC2" && path != "/" {
        plain(404, "no XML-RPC service here; use /RPC2\n")
    } else if request.body_length().is_some_and(|len| len > MAX_BODY) {
        plain(413, "request too large\n")
    } else {
        let mut body = Vec::new();
        let read = request
            .as_reader()
            .take(MAX_BODY as u64 + 1)
            .read_to_end(&mut body);
        match read {
            Err(_) => return, // the client went away
            Ok(_) if body.len() > MAX_BODY => plain(413, "request too large\n"),
            Ok(_) => match response_to_xml(&call_handler(&body, handler)) {
                Ok(xml) => Response::from_string(xml).with_header(text_xml()),
                Err(e) => plain(500, &format!("cannot write the response: {e}\n")),
            },
        }
    };
    // A client that gave up (timed out) is not our error.
    let _ = request.respond(response);
}

fn call_handler(body: &[u8], handler: &dyn Handler) -> Result<Value, Fault> {
    let text = std::str::from_utf8(body)
        .map_err(|_| Fault::new(FAULT_PARSE, "request body is not UTF-8"))?;
    let (method, params) = parse_call(text).map_err(|e| Fault::new(FAULT_PARSE, e))?;
    catch_unwind(AssertUnwindSafe(|| handler.call(&method, params))).unwrap_or_else(|_| {
        Err(Fault::new(
            FAULT_INTERNAL,
            format!("internal error while handling {method}"),
        ))
    })
}
