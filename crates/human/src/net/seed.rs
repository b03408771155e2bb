//! One lock over Burn's process-wide CPU generator.

/// Burn's CPU generator is one process-wide state, and parameters are drawn from it lazily.
/// Whoever seeds it and draws (a trainer creating its network, a test) holds this lock until
/// the draws are done, so that the numbers depend on the seed alone, whatever else runs in the
/// process.
pub fn seeded(seed: u64) -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let guard = LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    burn::tensor::Device::flex().seed(seed);
    guard
}
