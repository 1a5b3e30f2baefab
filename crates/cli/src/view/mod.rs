//! `fairgrasp view`: a page served on loopback that shows the scene live, with play / pause /
//! step / reset, policy, random and manual modes, joint sliders, the last step's reward terms
//! and an orbit camera. Frames come from the CPU renderer; every asset is in the binary.

mod camera;
mod scene_env;
mod server;
mod session;
#[cfg(test)]
mod tests;
mod twin;

use crate::eval_cmd::{check_frame_size, policy_and_env};
use anyhow::{Context, Result};
use fairgrasp_rl::train::HELD_OUT_SEED_BASE;
use session::Session;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args, Clone, Debug)]
pub struct ViewArgs {
    /// The environment (default: the model's, else FaArmGrasp-v0).
    #[arg(long = "env")]
    pub id: Option<String>,
    /// A saved model, for policy mode.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Port to listen on; 0 picks a free one (the URL is printed).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Address to listen on; loopback unless you mean to show the page to other machines.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// The digital twin's CNDE stream ("ip:port", e.g. 127.0.0.1:20005): twin mode shows its
    /// arm as it moves during a deployment rehearsal.
    #[arg(long)]
    pub twin: Option<String>,
    /// Frame size in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// First episode seed (episode k uses seed + k).
    #[arg(long, default_value_t = HELD_OUT_SEED_BASE)]
    pub seed: u64,
    /// Change the environment: `--set control.max_joint_delta=0.1`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

/// A running viewer: its address and the server, which [`Viewer::stop`] unblocks.
pub struct Viewer {
    pub addr: SocketAddr,
    server: Arc<tiny_http::Server>,
}

impl Viewer {
    /// Stops serving (the session thread ends when the server thread drops its sender).
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn stop(&self) {
        self.server.unblock();
    }
}

/// Builds the session and starts the simulation and HTTP threads.
pub fn start(args: &ViewArgs) -> Result<(Viewer, std::thread::JoinHandle<()>)> {
    check_frame_size(args.width, args.height)?;
    let (policy, id, table) =
        policy_and_env(args.id.as_deref(), args.model.as_deref(), &args.overrides)?;
    let env = scene_env::make_env(&id, &table)?;
    let twin = match &args.twin {
        Some(addr) => Some(twin::TwinView::connect(addr, env.scene().config().clone())?),
        None => None,
    };
    let session = Session::new(env, id, policy, args.seed, (args.width, args.height), twin)?;
    let bind = SocketAddr::new(args.bind, args.port);
    let server = tiny_http::Server::http(bind)
        .map_err(|e| anyhow::anyhow!("cannot listen on {bind}: {e}"))?;
    let addr = server
        .server_addr()
        .to_ip()
        .context("the server is not on an IP socket")?;
    let server = Arc::new(server);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("view-session".into())
        .spawn(move || session.run(rx))
        .context("cannot start the simulation thread")?;
    let http = Arc::clone(&server);
    let handle = std::thread::Builder::new()
        .name("view-http".into())
        .spawn(move || server::serve(&http, tx))
        .context("cannot start the HTTP thread")?;
    Ok((Viewer { addr, server }, handle))
}

pub fn run(args: &ViewArgs) -> Result<()> {
    let (viewer, http) = start(args)?;
    println!("fairgrasp view: http://{}/", viewer.addr);
    if !args.bind.is_loopback() {
        eprintln!(
            "warning: serving on {} — anyone who can reach it can drive the simulation",
            args.bind
        );
    }
    http.join()
        .map_err(|_| anyhow::anyhow!("the HTTP thread panicked"))
}
