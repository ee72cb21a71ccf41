import Foundation
@_exported import MonotrackFFI
#if canImport(CoreMedia) && canImport(CoreVideo)
import CoreMedia
import CoreVideo
#endif

/// Tracks faces in camera frames: the idiomatic Swift face of the generated
/// `MonotrackFFI.FaceTracker`.
///
/// Create one per camera stream and feed it frames from the video data output's queue:
///
/// ```swift
/// let tracker = try Monotrack.FaceTracker()            // video mode, default intrinsics
/// // in captureOutput(_:didOutput:from:)
/// let result = try tracker.process(sampleBuffer, orientation: orientation)
/// ```
///
/// Calls are synchronous. The native tracker is thread-safe (a mutex guards its state); this class
/// adds only a lock-protected timestamp, so it is `Sendable`, but frames should come from one serial
/// queue so that they arrive in time order. The native memory is freed when the last reference goes
/// (ARC; there is nothing to close).
public final class FaceTracker: @unchecked Sendable {
    private let native: MonotrackFFI.FaceTracker
    private let videoMode: Bool
    private let timestamps = MonotonicTimestamps()

    /// The configuration the tracker runs with.
    public let config: TrackerConfig

    /// Creates a tracker.
    ///
    /// - Parameter config: settings; `defaultTrackerConfig()` (video mode) when omitted.
    /// - Throws: `MonotrackError` (invalid config, model load).
    public init(config: TrackerConfig = defaultTrackerConfig()) throws {
        native = try MonotrackFFI.FaceTracker(config: config)
        self.config = config
        videoMode = config.runningMode == .video
    }

    #if canImport(CoreMedia) && canImport(CoreVideo)
    /// Tracks faces in a camera sample buffer (its image buffer and presentation timestamp).
    ///
    /// - Parameter orientation: how to make the buffer upright, e.g.
    ///   `FrameOrientation(videoRotationAngle:frontCamera:)`.
    /// - Returns: faces in the upright (rotated, mirrored as asked) image's pixel coordinates.
    /// - Throws: `FrameError` when the buffer has no image or an unsupported format;
    ///   `MonotrackError` from the SDK.
    public func process(_ sampleBuffer: CMSampleBuffer, orientation: FrameOrientation) throws -> TrackingResult {
        guard let pixelBuffer = CMSampleBufferGetImageBuffer(sampleBuffer) else {
            throw FrameError.invalidLayout("sample buffer has no image buffer")
        }
        return try process(pixelBuffer, orientation: orientation,
                           timestamp: CMSampleBufferGetPresentationTimeStamp(sampleBuffer))
    }

    /// Tracks faces in a pixel buffer (BGRA, NV12 or 8-bit gray), read in place.
    ///
    /// - Parameter timestamp: the frame's presentation time; used in video mode, where it is made
    ///   strictly increasing (a repeated or earlier time becomes the previous one plus 1 ns).
    /// - Throws: `FrameError`; `MonotrackError` from the SDK.
    public func process(_ pixelBuffer: CVPixelBuffer, orientation: FrameOrientation, timestamp: CMTime) throws
        -> TrackingResult
    {
        try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try processFrame(bytes: data, desc: desc, timestampNs: Self.nanoseconds(timestamp))
        }
    }

    /// Detects faces in one still pixel buffer; touches no tracking state.
    ///
    /// - Throws: `FrameError`; `MonotrackError` from the SDK.
    public func processImage(_ pixelBuffer: CVPixelBuffer, orientation: FrameOrientation) throws -> TrackingResult {
        try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try native.processImage(bytes: data, desc: desc)
        }
    }
    #endif

    /// Tracks faces in described bytes (any `PixelFormat`); in image mode every call detects afresh.
    ///
    /// - Throws: `MonotrackError.InvalidFrame` when `bytes` does not match `desc`; other
    ///   `MonotrackError`s from the SDK.
    public func processFrame(bytes: Data, desc: FrameDesc, timestampNs: Int64) throws -> TrackingResult {
        guard videoMode else { return try native.processImage(bytes: bytes, desc: desc) }
        return try native.processFrame(bytes: bytes, desc: desc, timestampNs: timestamps.next(timestampNs))
    }

    /// Forgets all tracks and the user's estimated face shape (camera switch, new person).
    public func reset() {
        native.reset()
        timestamps.reset()
    }

    /// Sets the targets each face's point of gaze is located among (e.g. `screenTarget(...)`
    /// for the device's own screen); an empty list turns location off.
    ///
    /// - Throws: `MonotrackError.InvalidConfig` for a bad target or a repeated id.
    public func setGazeTargets(_ targets: [GazeTarget]) throws {
        try native.setGazeTargets(targets: targets)
    }

    /// The user looked at `point` on target `targetId` at `timestampNs` (a tap; the frames'
    /// clock): refines the user's own gaze offset from the next frame. Returns the taps so far.
    ///
    /// - Throws: `MonotrackError.InvalidConfig` (unknown target), `.InvalidFrame` (no frame with a
    ///   face within 250 ms).
    @discardableResult
    public func addCalibrationPoint(targetId: String, point: PlanePoint, timestampNs: Int64) throws -> UInt32 {
        try native.addCalibrationPoint(targetId: targetId, point: point, timestampNs: timestampNs)
    }

    /// Forgets the gaze calibration (a new user).
    public func resetGazeCalibration() {
        native.resetGazeCalibration()
    }

    #if canImport(CoreMedia)
    /// `time` in nanoseconds (0 for an invalid time, which the timestamp guard then moves forward).
    static func nanoseconds(_ time: CMTime) -> Int64 {
        guard time.isValid, time.isNumeric else { return 0 }
        return CMTimeConvertScale(time, timescale: 1_000_000_000, method: .roundHalfAwayFromZero).value
    }
    #endif
}
