import Foundation
import MonotrackFFI

/// What a live-stream `FaceTracker` delivers for one frame, as `LiveEvents` streams it.
public enum LiveEvent: Sendable {
    /// The frame's faces; `framesDropped` frames were skipped before it because the tracker was busy.
    case faces(LiveStreamResult)
    /// Tracking the frame taken at `timestampMs` failed, or a tap at that time could not be used;
    /// the stream goes on with the next one.
    case failed(timestampMs: Int64, framesDropped: UInt64, error: MonotrackError)

    /// The timestamp the frame, or the tap, was submitted with, milliseconds.
    public var timestampMs: Int64 {
        switch self {
        case .faces(let r): return r.timestampMs
        case .failed(let t, _, _): return t
        }
    }

    /// Frames skipped since the previous event because the tracker was busy.
    public var framesDropped: UInt64 {
        switch self {
        case .faces(let r): return r.framesDropped
        case .failed(_, let d, _): return d
        }
    }
}

/// A `LiveStreamListener` that turns a live-stream tracker's deliveries into an `AsyncStream`, in
/// timestamp order:
///
/// ```swift
/// let events = LiveEvents()
/// let tracker = try FaceTracker(options: FaceTrackerOptions(runningMode: .liveStream), listener: events)
/// Task { for await event in events.events { if case .faces(let r) = event { show(r.result) } } }
/// // in captureOutput(_:didOutput:from:)
/// try tracker.detectAsync(sampleBuffer, orientation: orientation)
/// // on stop
/// tracker.shutdown()
/// events.finish()
/// ```
///
/// Build the tracker off the main actor: it loads the models.
public final class LiveEvents: LiveStreamListener, Sendable {
    private let continuation: AsyncStream<LiveEvent>.Continuation

    /// Every event, in timestamp order. A consumer slower than the tracker loses the oldest events
    /// beyond the buffer; the stream ends with `finish()`.
    public let events: AsyncStream<LiveEvent>

    /// A listener whose stream keeps the newest `bufferingNewest` events for a slow consumer.
    public init(bufferingNewest: Int = 8) {
        (events, continuation) = AsyncStream<LiveEvent>.makeStream(bufferingPolicy: .bufferingNewest(bufferingNewest))
    }

    deinit {
        continuation.finish()
    }

    /// Ends `events`. Call it after the tracker's `shutdown()`, which returns only once the
    /// listener will not be called again, so no event is cut off; idempotent.
    public func finish() {
        continuation.finish()
    }

    /// Called by the tracker's worker with one frame's faces.
    public func onResult(result: LiveStreamResult) {
        continuation.yield(.faces(result))
    }

    /// Called by the tracker's worker when a frame or a tap could not be used.
    public func onError(timestampMs: Int64, framesDropped: UInt64, error: MonotrackError) {
        continuation.yield(.failed(timestampMs: timestampMs, framesDropped: framesDropped, error: error))
    }
}
