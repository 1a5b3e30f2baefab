//! What the host is, to print beside every absolute figure (hosts differ: an AVX-512 Xeon and an
//! AVX2-only EPYC of the same machine kind ran the default training in 30 s and 102 s).

/// The CPU's model name (`/proc/cpuinfo`), to print beside every absolute figure.
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}
