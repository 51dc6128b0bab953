//! `fibrefit view RESULT [--out page.html] [--open]`: the viewer page ([`crate::api::view`]),
//! written to a file and/or served on 127.0.0.1 and opened in the browser.

use crate::api::view::{self as view_api, ViewRequest};
use anyhow::{anyhow, Result};
use clap::Args;
use std::io::{Read, Write};
use std::path::PathBuf;

#[derive(Debug, Args)]
#[command(after_help = "\
THE PAGE: one self-contained HTML file (no network: the script, the style and the data are inline)
with a WebGL2 viewer: the material on a swatch, a sphere, the torus and a draped cloth, a light
you drag around the hemisphere, the camera you drag around the object, exposure and a fill light
from the camera (as `render`'s), the fibre direction drawn; the exact model through the exported
shader (GLSL ES 3.00) beside the glTF route's material (what `export --gltf` writes, drawn through
the gltf rung's shader); for data with enough directions the measured against the fitted BRDF
for the light's direction; the parameter table with standard errors, the verdict and the warnings.
The page opens with the set-up of its address's hash, e.g. page.html#light=40,120&camera=50,270&exposure=2&fill=0.25&object=swatch
(docs/guide/view.md).
--open serves the page on 127.0.0.1 only (a free port) and opens the system's browser; Ctrl-C stops it.")]
pub struct ViewArgs {
    /// A fitted result (.json) or any parameter file `eval` accepts
    pub result: PathBuf,
    /// The page to write [default: RESULT with the extension .html, unless --open]
    #[arg(long, value_name = "FILE.html")]
    pub out: Option<PathBuf>,
    /// Measurements to compare with [default: the data file the result names, beside it]
    #[arg(long, value_name = "FILE")]
    pub data: Option<PathBuf>,
    /// Serve the page on 127.0.0.1 and open it in the browser (until Ctrl-C)
    #[arg(long)]
    pub open: bool,
    /// No summary on stderr
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &ViewArgs) -> Result<()> {
    let out = match (&args.out, args.open) {
        (Some(p), _) => Some(p.clone()),
        (None, true) => None,
        (None, false) => Some(args.result.with_extension("html")),
    };
    let req = ViewRequest {
        result: args.result.clone(),
        data: args.data.clone(),
        progress: crate::progress::Progress::new(args.quiet),
    };
    let page = match &out {
        Some(path) => view_api::write(&req, path)?,
        None => view_api::prepare(&req)?,
    };
    if !args.quiet {
        let (shown, note) = &page.comparison;
        let what = if *shown { "measured against fitted: shown" } else { "measured against fitted: not shown" };
        match &out {
            Some(p) => eprintln!("wrote {} ({} bytes; {what}: {note})", p.display(), page.html.len()),
            None => eprintln!("{what}: {note}"),
        }
    }
    if args.open {
        serve(&page.html)?;
    }
    Ok(())
}

/// Serve `html` at http://127.0.0.1:PORT/ (a free port, this machine only), open it in the
/// system's browser, and answer until the process is stopped (Ctrl-C).
fn serve(html: &str) -> Result<()> {
    let listener = std::net::TcpListener::bind(("127.0.0.1", 0))
        .map_err(|e| anyhow!("--open: cannot listen on 127.0.0.1: {e}"))?;
    let url = format!("http://{}/", listener.local_addr()?);
    eprintln!("serving the page at {url} (this machine only); Ctrl-C stops");
    if let Err(e) = open_browser(&url) {
        eprintln!("could not open a browser ({e}): open {url} yourself");
    }
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        let _ = stream.set_read_timeout(Some(std::time::Duration::from_secs(5)));
        let mut head = [0u8; 2048];
        let n = stream.read(&mut head).unwrap_or(0);
        let line = String::from_utf8_lossy(&head[..n]);
        let target = line.split_whitespace().nth(1).unwrap_or("");
        let path = target.split(['?', '#']).next().unwrap_or("");
        let reply = if matches!(path, "/" | "/index.html") {
            format!(
                "HTTP/1.1 200 OK\r\nContent-Type: text/html; charset=utf-8\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n{html}",
                html.len()
            )
        } else {
            "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_string()
        };
        let _ = stream.write_all(reply.as_bytes());
    }
    Ok(())
}

/// Open `url` with the system's opener (xdg-open, open, start).
fn open_browser(url: &str) -> std::io::Result<()> {
    let mut cmd = if cfg!(target_os = "macos") {
        std::process::Command::new("open")
    } else if cfg!(windows) {
        let mut c = std::process::Command::new("cmd");
        c.args(["/C", "start", ""]);
        c
    } else {
        std::process::Command::new("xdg-open")
    };
    cmd.arg(url)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map(|_| ())
}
