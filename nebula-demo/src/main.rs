//! `nebula-demo`: renders a Nebula planet (windowed or headless).

fn main() -> std::process::ExitCode {
    eprintln!(
        "nebula-demo: not yet — the renderer lands with its own issue. \
         The math and voxel crates are ready: `cargo test --workspace`."
    );
    std::process::ExitCode::from(2)
}
