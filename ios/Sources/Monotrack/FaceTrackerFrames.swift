// CoreMedia and CoreVideo exist on Apple platforms only: on Linux (bindings/tests/run-swift.sh) this
// file is empty.
#if canImport(CoreMedia) && canImport(CoreVideo)
import CoreMedia
import CoreVideo
import Foundation
import MonotrackFFI

/// Camera buffers for the generated `FaceTracker`: each call reads the buffer in place
/// (`CVPixelBuffer.withMonotrackFrame`) and passes it to the running mode's call of the same name.
///
/// ```swift
/// let tracker = try FaceTracker(options: FaceTrackerOptions(runningMode: .video))
/// // in captureOutput(_:didOutput:from:)
/// let result = try tracker.detectForVideo(sampleBuffer, orientation: orientation)
/// ```
extension FaceTracker {
    /// Image mode: the faces of one still pixel buffer (BGRA, NV12 or 8-bit gray).
    ///
    /// - Parameter orientation: how to make the buffer upright, e.g. `FrameOrientation(exif)`.
    /// - Throws: `FrameError` for an unsupported or unlockable buffer; `MonotrackError` from the
    ///   SDK (`.InvalidState` when the tracker runs in another mode or was shut down).
    public func detect(_ pixelBuffer: CVPixelBuffer, orientation: FrameOrientation) throws -> TrackingResult {
        try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try detect(bytes: data, desc: desc)
        }
    }

    /// Video mode: the faces of a camera or movie sample buffer at its presentation time, tracked
    /// from the frames before.
    ///
    /// - Parameter orientation: how to make the buffer upright, e.g.
    ///   `FrameOrientation(videoRotationAngle:frontCamera:)`.
    /// - Throws: `FrameError` for a buffer without an image or a presentation time, or of an
    ///   unsupported format; `MonotrackError.InvalidTimestamp` when its time, in milliseconds, is
    ///   not after the previous frame's (a restarted camera needs `reset()`); other
    ///   `MonotrackError`s from the SDK.
    public func detectForVideo(_ sampleBuffer: CMSampleBuffer, orientation: FrameOrientation) throws -> TrackingResult {
        let (pixelBuffer, timestampMs) = try Self.frame(of: sampleBuffer)
        return try detectForVideo(pixelBuffer, orientation: orientation, timestampMs: timestampMs)
    }

    /// Video mode: the faces of a pixel buffer taken at `timestampMs` (for buffers that come
    /// without a sample buffer, such as ARKit's `ARFrame.capturedImage` with its `timestamp` in
    /// milliseconds).
    ///
    /// - Throws: as `detectForVideo(_:orientation:)` for a sample buffer.
    public func detectForVideo(_ pixelBuffer: CVPixelBuffer, orientation: FrameOrientation, timestampMs: Int64) throws
        -> TrackingResult
    {
        try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try detectForVideo(bytes: data, desc: desc, timestampMs: timestampMs)
        }
    }

    /// Live-stream mode: hands a camera sample buffer, at its presentation time, to the tracker's
    /// worker and returns at once (the pixels are copied first, so the camera may reuse the
    /// buffer). The result reaches the listener given to the tracker, e.g. `LiveEvents`.
    ///
    /// - Returns: `true` when a frame still waiting was replaced by this one.
    /// - Throws: as `detectForVideo(_:orientation:)`.
    @discardableResult
    public func detectAsync(_ sampleBuffer: CMSampleBuffer, orientation: FrameOrientation) throws -> Bool {
        let (pixelBuffer, timestampMs) = try Self.frame(of: sampleBuffer)
        return try detectAsync(pixelBuffer, orientation: orientation, timestampMs: timestampMs)
    }

    /// Live-stream mode: hands a pixel buffer taken at `timestampMs` to the tracker's worker and
    /// returns at once.
    ///
    /// - Returns: `true` when a frame still waiting was replaced by this one.
    /// - Throws: as `detectForVideo(_:orientation:)`.
    @discardableResult
    public func detectAsync(_ pixelBuffer: CVPixelBuffer, orientation: FrameOrientation, timestampMs: Int64) throws
        -> Bool
    {
        try pixelBuffer.withMonotrackFrame(orientation: orientation) { data, desc in
            try detectAsync(bytes: data, desc: desc, timestampMs: timestampMs)
        }
    }

    /// The sample buffer's image and its presentation time in milliseconds (the SDK's unit).
    private static func frame(of sampleBuffer: CMSampleBuffer) throws -> (CVPixelBuffer, Int64) {
        guard let pixelBuffer = CMSampleBufferGetImageBuffer(sampleBuffer) else {
            throw FrameError.invalidLayout("sample buffer has no image buffer")
        }
        let time = CMSampleBufferGetPresentationTimeStamp(sampleBuffer)
        // An invalid time has no place in the stream's clock; inventing one would hide the gap.
        guard time.isValid, time.isNumeric else { throw FrameError.noPresentationTime }
        return (pixelBuffer, CMTimeConvertScale(time, timescale: 1000, method: .roundHalfAwayFromZero).value)
    }
}
#endif
