//! The viewer's HTTP face (tiny_http): the embedded page, `GET /frame.png`, `GET /state` and
//! `POST /control`. Bad input gets a 400 naming the problem; nothing here panics on it.

use super::camera::Orbit;
use super::session::{Control, Request};
use std::io::Read;
use std::sync::mpsc::{Sender, channel};
use tiny_http::{Header, Method, Response, Server};

const INDEX_HTML: &str = include_str!("assets/index.html");
const VIEWER_JS: &str = include_str!("assets/viewer.js");
const VIEWER_CSS: &str = include_str!("assets/viewer.css");

/// Largest `POST /control` body read (a joints command is well under 1 KiB).
const MAX_BODY: u64 = 16 * 1024;

type Reply = Response<std::io::Cursor<Vec<u8>>>;

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("static header is valid")
}

fn text(status: u16, body: impl Into<String>) -> Reply {
    Response::from_string(body.into())
        .with_status_code(status)
        .with_header(header("Content-Type", "text/plain; charset=utf-8"))
}

fn content(body: &str, kind: &str) -> Reply {
    Response::from_string(body).with_header(header("Content-Type", kind))
}

/// Answers requests until the server is unblocked or fails.
pub fn serve(server: &Server, session: Sender<Request>) {
    for mut request in server.incoming_requests() {
        let url = request.url().to_string();
        let (path, query) = url.split_once('?').unwrap_or((&url, ""));
        let response = match (request.method(), path) {
            (Method::Get, "/" | "/index.html") => content(INDEX_HTML, "text/html; charset=utf-8"),
            (Method::Get, "/viewer.js") => content(VIEWER_JS, "text/javascript; charset=utf-8"),
            (Method::Get, "/viewer.css") => content(VIEWER_CSS, "text/css; charset=utf-8"),
            (Method::Get, "/frame.png") => frame(&session, query),
            (Method::Get, "/state") => state(&session),
            (Method::Post, "/control") => {
                let mut body = String::new();
                match request.as_reader().take(MAX_BODY).read_to_string(&mut body) {
                    Ok(_) => control(&session, &body),
                    Err(e) => text(400, format!("cannot read the body: {e}")),
                }
            }
            (
                _,
                "/" | "/index.html" | "/viewer.js" | "/viewer.css" | "/frame.png" | "/state"
                | "/control",
            ) => text(
                405,
                format!("{} is not allowed on {path}", request.method()),
            ),
            _ => text(404, format!("no such page: {path}")),
        };
        // The client may have gone; nothing to do about it.
        let _ = request.respond(response);
    }
}

fn ask<T>(session: &Sender<Request>, make: impl FnOnce(Sender<T>) -> Request) -> Result<T, Reply> {
    let (tx, rx) = channel();
    session
        .send(make(tx))
        .map_err(|_| text(503, "the simulation has stopped"))?;
    rx.recv()
        .map_err(|_| text(503, "the simulation has stopped"))
}

fn frame(session: &Sender<Request>, query: &str) -> Reply {
    let orbit = match Orbit::from_query(query) {
        Ok(o) => o,
        Err(e) => return text(400, e),
    };
    match ask(session, |tx| Request::Frame(orbit, tx)) {
        Ok(Ok((w, h, rgb))) => match encode_png(w, h, &rgb) {
            Ok(bytes) => Response::from_data(bytes)
                .with_header(header("Content-Type", "image/png"))
                .with_header(header("Cache-Control", "no-store")),
            Err(e) => text(500, format!("cannot encode the frame: {e}")),
        },
        Ok(Err(e)) => text(500, format!("cannot render: {e}")),
        Err(reply) => reply,
    }
}

fn state(session: &Sender<Request>) -> Reply {
    match ask(session, Request::State) {
        Ok(value) => content(&value.to_string(), "application/json"),
        Err(reply) => reply,
    }
}

fn control(session: &Sender<Request>, body: &str) -> Reply {
    let command: Control = match serde_json::from_str(body) {
        Ok(c) => c,
        Err(e) => {
            return text(
                400,
                format!(
                    "bad command ({e}); expected JSON such as {{\"cmd\":\"step\"}} with cmd one of \
                     play, pause, step, reset, mode, joints, gripper"
                ),
            );
        }
    };
    match ask(session, |tx| Request::Control(command, tx)) {
        Ok(Ok(())) => content("{\"ok\":true}", "application/json"),
        Ok(Err(e)) => text(400, e),
        Err(reply) => reply,
    }
}

/// RGB bytes as a PNG file; fast compression, since frames are streamed.
pub fn encode_png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(out)
}
