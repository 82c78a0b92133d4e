//! The server under concurrent load (`objview_server::load`, what `objview bench serve` runs):
//! eight clients at once, each playing episodes of depth fetches and moves on a tiny built-in
//! object whose scene is not prepared yet. Every client must finish every episode without an
//! error (no starvation, no lost or refused request), the eight concurrent first creates must
//! share one scene build, and no client may be served much later than the others: its longest
//! wait for a step and its total time are bounded relative to the run's own median and to the
//! fastest client, not by absolute timings.

mod common;

use common::*;
use objview_server::load::{run_load, LoadConfig};

#[test]
fn eight_concurrent_clients_all_finish_fairly_on_one_shared_scene() {
    let (cfg, _tmp) = config();
    let server = start(&cfg);
    assert_eq!(server.state.scenes.stats().builds, 0);
    let clients = 8;
    let episodes_per_client = 2;
    let budget = 4;
    let load = LoadConfig {
        url: server.url(),
        token: None,
        split: "hidden".into(),
        object: "cube".into(),
        view_space: "whole".into(),
        clients,
        episodes_per_client,
        budget,
        seed: 7,
        fetch_depth: true,
        candidate_set: "tammes-128".into(),
    };
    let r = run_load(&load).expect("every client completes its episodes without an error");
    eprintln!("load: {r:?}");
    assert_eq!(r.episodes, clients * episodes_per_client, "{r:?}");
    assert_eq!(r.steps, clients * episodes_per_client * budget, "{r:?}");
    assert_eq!(r.client.samples, r.steps, "{r:?}");
    assert_eq!(r.server.samples, r.steps, "every action answer has its Server-Timing: {r:?}");
    assert_eq!(r.create.samples, r.episodes, "{r:?}");
    assert_eq!(r.depth.samples, r.steps, "{r:?}");
    // Every create and step ran on an engine lane (one single-thread pool per core).
    assert!(server.state.engine_lanes.jobs_run() >= r.episodes + r.steps, "{r:?}");

    // The first creates of all eight clients arrive together on a cold cache: one build, the
    // other requests wait for it and reuse it, as does every later episode.
    let stats = server.state.scenes.stats();
    assert_eq!(stats.builds, 1, "{stats:?}");
    assert_eq!(stats.hits as usize, r.episodes - 1, "{stats:?}");

    // Fairness. Steps queue for the cores first come first served, so the clients advance in
    // step (the longest wait is about twice the median, the slowest client within a few percent
    // of the fastest); a client served after the others' episodes would wait about the whole
    // run and finish long after them. The bounds leave room for a busy test machine.
    assert!(r.max_wait.ms.is_finite() && r.client.p50_ms > 0.0, "{r:?}");
    assert!(
        r.max_wait.over_p50 <= 12.0,
        "client {} waited {:.1} ms for one step, {:.1}× the median: {r:?}",
        r.max_wait.client,
        r.max_wait.ms,
        r.max_wait.over_p50
    );
    let (fastest, slowest) = r.client_seconds;
    assert!(fastest > 0.0 && slowest >= fastest, "{r:?}");
    assert!(
        slowest <= 2.5 * fastest,
        "the slowest client took {slowest:.3} s, the fastest {fastest:.3} s: {r:?}"
    );
    server.stop();
}
