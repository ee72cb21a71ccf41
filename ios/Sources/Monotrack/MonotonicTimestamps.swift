import Foundation

/// Makes frame timestamps strictly increasing, as video and live-stream tracking need: a repeated
/// or earlier time becomes the previous one plus 1 ns. Lock-protected, so trackers that hold one
/// stay `Sendable`.
final class MonotonicTimestamps: @unchecked Sendable {
    private let lock = NSLock()
    private var last: Int64?

    /// `t`, or the previous timestamp plus 1 ns when `t` is not after it.
    func next(_ t: Int64) -> Int64 {
        lock.lock()
        defer { lock.unlock() }
        let next = last.map { t <= $0 ? $0 + 1 : t } ?? t
        last = next
        return next
    }

    /// Forgets the previous timestamp.
    func reset() {
        lock.lock()
        last = nil
        lock.unlock()
    }
}
