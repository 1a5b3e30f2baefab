//! [`PeriodicServer`]: a TCP server whose thread accepts clients and, every period, hands them
//! to a tick that sends (the twin's pose and camera feeds).

use std::io;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A running server; its thread stops when it is dropped.
pub(crate) struct PeriodicServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl PeriodicServer {
    /// Listens on `bind` (port 0: any free port). Each accepted client is set up by `prepare`
    /// (dropped if it fails); every `period` `tick` gets the clients, to send to them and drop
    /// those that fail.
    pub(crate) fn spawn(
        name: &str,
        bind: SocketAddr,
        period: Duration,
        prepare: fn(&TcpStream) -> io::Result<()>,
        mut tick: impl FnMut(&mut Vec<TcpStream>) + Send + 'static,
    ) -> io::Result<Self> {
        let listener = TcpListener::bind(bind)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name(name.into())
                .spawn(move || {
                    let mut clients: Vec<TcpStream> = Vec::new();
                    let mut next = Instant::now();
                    while !stop.load(Ordering::SeqCst) {
                        while let Ok((stream, _)) = listener.accept() {
                            if prepare(&stream).is_ok() {
                                clients.push(stream);
                            }
                        }
                        tick(&mut clients);
                        next += period;
                        let now = Instant::now();
                        if next > now {
                            std::thread::sleep(next - now);
                        } else {
                            next = now;
                        }
                    }
                })?
        };
        Ok(Self {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// The TCP address clients connect to.
    pub(crate) fn local_addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for PeriodicServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
