import Foundation
@_exported import MonotrackFFI
#if canImport(CoreMedia) && canImport(CoreVideo)
import CoreMedia
import CoreVideo
#endif

/// What a `LiveTracker` delivers for one frame.
public enum LiveEvent: Sendable {
    /// The frame's faces; `framesDropped` frames were skipped before it because the tracker was busy.
    case faces(LiveStreamResult)
    /// Tracking the frame taken at `timestampNs` failed, or a tap at that time could not be used;
    /// the stream goes on with the next one.
    case failed(timestampNs: Int64, framesDropped: UInt64, error: MonotrackError)
}

/// The face tracker in live-stream mode (as MediaPipe's `liveStream`): `process` copies the frame and
/// returns at once, one native worker thread tracks it, and the result arrives later on `events`.
/// While the worker is busy the newest frame waits and replaces any older waiting one, so a slow
/// device skips frames instead of falling behind; each event says how many were skipped.
///
/// ```swift
/// let tracker = try await Task.detached { try LiveTracker() }.value   // loads models: off the main actor
/// Task { for await event in tracker.events { if case .faces(let r) = event { show(r.result) } } }
/// // in captureOutput(_:didOutput:from:)
/// try tracker.process(sampleBuffer, orientation: orientation)
/// ```
public final class LiveTracker: @unchecked Sendable {
    private let native: MonotrackFFI.LiveFaceTracker
    private let continuation: AsyncStream<LiveEvent>.Continuation
    private let timestamps = MonotonicTimestamps()

    /// Every event, in timestamp order. Buffers the newest 8 for a slow consumer; the stream
    /// finishes when the tracker is shut down.
    public let events: AsyncStream<LiveEvent>

    /// Creates the tracker and starts its worker. `config.runningMode` is not read.
    ///
    /// - Throws: `MonotrackError` (invalid config, model load).
    public init(config: TrackerConfig = defaultTrackerConfig()) throws {
        let (stream, continuation) = AsyncStream<LiveEvent>.makeStream(bufferingPolicy: .bufferingNewest(8))
        events = stream
        self.continuation = continuation
        native = try MonotrackFFI.LiveFaceTracker(config: config, listener: Forward(continuation))
    }

    deinit {
        native.shutdown()
        continuation.finish()
    }

    #if canImport(CoreMedia) && canImport(CoreVideo)
    /// Submits a camera sample buffer (its image buffer and presentation time) and returns at once.
    ///
    /// - Returns: `true` when a frame still waiting was replaced by this one.
    /// - Throws: `FrameError` for a buffer without an image or of an unsupported format;
    ///   `MonotrackError.InvalidFrame` for bytes that do not match their description.
    @discardableResult
    public func process(_ sampleBuffer: CMSampleBuffer, orientation: FrameOrientation) throws -> Bool {
        guard let pixelBuffer = CMSampleBufferGetImageBuffer(sampleBuffer) else {
            throw FrameError.invalidLayout("sample buffer has no image buffer")
        }
        let t = FaceTracker.nanoseconds(CMSampleBufferGetPresentationTimeStamp(sampleBuffer))
        return try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try native.processAsync(bytes: data, desc: desc, timestampNs: timestamps.next(t))
        }
    }
    #endif

    /// Submits described bytes (any `PixelFormat`; copied before it returns) taken at `timestampNs`
    /// and returns at once. A repeated or earlier time becomes the previous one plus 1 ns.
    ///
    /// - Returns: `true` when a frame still waiting was replaced by this one.
    /// - Throws: `MonotrackError.InvalidFrame` for bytes that do not match `desc`, or after `shutdown()`.
    @discardableResult
    public func process(bytes: Data, desc: FrameDesc, timestampNs: Int64) throws -> Bool {
        try native.processAsync(bytes: bytes, desc: desc, timestampNs: timestamps.next(timestampNs))
    }

    /// Sets the targets each face's point of gaze is located among (as `FaceTracker.setGazeTargets`);
    /// frames from the next one on use them.
    /// - Throws: `MonotrackError.InvalidConfig` for a bad target or a repeated id.
    public func setGazeTargets(_ targets: [GazeTarget]) throws {
        try native.setGazeTargets(targets: targets)
    }

    /// A tap: the user looked at `point` on the target `targetId` at `timestampNs` (the frames'
    /// clock). Learnt on the worker before the next frame; a tap it cannot use (no face within
    /// 250 ms of it) arrives as `LiveEvent.failed` with the tap's time.
    /// - Throws: `MonotrackError.InvalidConfig` for an unknown target, a non-finite point or the
    ///   gaze output turned off.
    public func addCalibrationPoint(targetId: String, point: PlanePoint, timestampNs: Int64) throws {
        try native.addCalibrationPoint(targetId: targetId, point: point, timestampNs: timestampNs)
    }

    /// Forgets the tap calibration (a new user) before the next frame.
    public func resetGazeCalibration() {
        native.resetGazeCalibration()
    }

    /// Stops the worker (a frame being tracked finishes and is delivered, a waiting one is dropped)
    /// and finishes `events`. Idempotent.
    public func shutdown() {
        native.shutdown()
        continuation.finish()
    }
}

/// Hands the native worker's calls to the stream.
private final class Forward: LiveStreamListener, @unchecked Sendable {
    private let continuation: AsyncStream<LiveEvent>.Continuation

    init(_ continuation: AsyncStream<LiveEvent>.Continuation) {
        self.continuation = continuation
    }

    func onResult(result: LiveStreamResult) {
        continuation.yield(.faces(result))
    }

    func onError(timestampNs: Int64, framesDropped: UInt64, error: MonotrackError) {
        continuation.yield(.failed(timestampNs: timestampNs, framesDropped: framesDropped, error: error))
    }
}
