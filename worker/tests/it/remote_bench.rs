//! Runs the policy-call overhead benchmark; ignored by default because it measures, it does not
//! test. `cargo test --release -p kitchen-r-worker --test it remote_bench -- --ignored --nocapture`
//! (`REMOTE_BENCH_CALLS` sets the number of calls, 2000 by default).

#[test]
#[ignore = "a benchmark: run it in release with --ignored --nocapture"]
fn policy_call_overhead_on_loopback() {
    let n = std::env::var("REMOTE_BENCH_CALLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000);
    let r = kitchen_r_contract::bench::call_overhead(n).unwrap();
    println!(
        "policy call overhead, 2x128x128 RAW_RGB8, loopback: p50 {:.0} us, p99 {:.0} us, mean {:.0} us over {} calls",
        r.p50_us, r.p99_us, r.mean_us, r.calls
    );
}
