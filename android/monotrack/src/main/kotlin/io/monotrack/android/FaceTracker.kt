package io.monotrack.android

import androidx.camera.core.ImageProxy
import io.monotrack.MonotrackException
import io.monotrack.RunningMode
import io.monotrack.TrackerConfig
import io.monotrack.TrackingResult
import io.monotrack.defaultTrackerConfig
import java.io.Closeable
import java.nio.ByteBuffer
import io.monotrack.FaceTracker as FfiFaceTracker

/**
 * Tracks faces in camera frames: the idiomatic Android face of the generated `io.monotrack.FaceTracker`.
 *
 * Create one per camera stream, feed it frames from a single analysis thread (CameraX's analyzer
 * executor), read [TrackingResult]s, and [close] it when the stream stops: close frees the native
 * tracker (models, buffers, tracks) at once instead of waiting for the garbage collector.
 *
 * Calls are synchronous and return when the frame is processed; the underlying native object is
 * thread-safe (its state sits behind a mutex), so a stray call from another thread is correct but
 * waits for the current frame.
 *
 * ```
 * val tracker = FaceTracker()                       // video mode, default intrinsics
 * analysis.setAnalyzer(executor) { image ->
 *     image.use { val result = tracker.process(it, mirrored = true); overlay.post { overlay.show(result) } }
 * }
 * // on stop: tracker.close()
 * ```
 *
 * @param config tracker settings; [defaultTrackerConfig] (video mode) when omitted.
 * @throws MonotrackException.InvalidConfig when [config] is out of range.
 * @throws MonotrackException.ModelLoad when the bundled models fail to load.
 */
public class FaceTracker(config: TrackerConfig = defaultTrackerConfig()) : Closeable {
    private val native = FfiFaceTracker(config)
    private val timestamps = MonotonicTimestamps()

    // Read once: asking the native object per frame would cross the FFI and allocate a record.
    private val videoMode = config.runningMode == RunningMode.VIDEO

    @Volatile
    private var closed = false

    /** The configuration the tracker runs with. */
    public val config: TrackerConfig
        get() = checkOpen().config()

    /**
     * Tracks faces in a CameraX frame in place: plane 0 (Y) is passed as a [io.monotrack.PixelFormat.GRAY8]
     * frame with its row stride and the image's `rotationDegrees`, no pixel is copied on the Kotlin side.
     * The caller keeps ownership of [image] and closes it after this returns.
     *
     * In video mode the frame's sensor timestamp drives tracking; a non-increasing timestamp is
     * nudged forward by 1 ns (see [MonotonicTimestamps]). In image mode every call detects afresh.
     *
     * @param mirrored true for the front camera, so that results match the mirrored preview.
     * @return faces in the upright (rotated, mirrored as asked) image's pixel coordinates.
     * @throws MonotrackException.InvalidFrame when the image is not YUV_420_888 or its planes are inconsistent.
     * @throws MonotrackException.Internal on a bug in the SDK.
     * @throws IllegalStateException when called after [close].
     */
    public fun process(image: ImageProxy, mirrored: Boolean): TrackingResult {
        val frame = image.lumaFrame(mirrored)
        return processFrame(frame.bytes, frame.desc, image.imageInfo.timestamp)
    }

    /**
     * Tracks faces in a described frame held in a direct [ByteBuffer] (any [io.monotrack.PixelFormat]).
     *
     * @param timestampNs frame time in nanoseconds; used in video mode, must increase (it is
     *   made strictly increasing here).
     * @throws MonotrackException.InvalidFrame when [bytes] does not match [desc].
     * @throws MonotrackException.Internal on a bug in the SDK.
     * @throws IllegalStateException when called after [close].
     */
    public fun processFrame(bytes: ByteBuffer, desc: io.monotrack.FrameDesc, timestampNs: Long): TrackingResult {
        val tracker = checkOpen()
        return if (videoMode) {
            tracker.processFrame(bytes, desc, timestamps.next(timestampNs))
        } else {
            tracker.processImage(bytes, desc)
        }
    }

    /**
     * Detects faces in a single still image; touches no tracking state.
     *
     * @throws MonotrackException.InvalidFrame when [bytes] does not match [desc].
     * @throws MonotrackException.Internal on a bug in the SDK.
     * @throws IllegalStateException when called after [close].
     */
    public fun processImage(bytes: ByteBuffer, desc: io.monotrack.FrameDesc): TrackingResult =
        checkOpen().processImage(bytes, desc)

    /**
     * Forgets all tracks and the user's estimated face shape (call on a camera switch or when a
     * different person appears).
     *
     * @throws IllegalStateException when called after [close].
     */
    public fun reset() {
        checkOpen().reset()
        timestamps.reset()
    }

    /**
     * Sets the targets each face's point of gaze is located among (e.g. [io.monotrack.screenTarget]
     * for the phone's own screen); an empty list turns location off.
     *
     * @throws MonotrackException.InvalidConfig for a bad target or a repeated id.
     */
    public fun setGazeTargets(targets: List<io.monotrack.GazeTarget>): Unit = checkOpen().setGazeTargets(targets)

    /**
     * The user looked at [point] on target [targetId] at [timestampNs] (a tap; the frames' clock):
     * refines the user's own gaze offset from the next frame. Returns the taps so far.
     *
     * @throws MonotrackException.InvalidConfig for an unknown target.
     * @throws MonotrackException.InvalidFrame when no frame with a face lies within 250 ms.
     */
    public fun addCalibrationPoint(targetId: String, point: io.monotrack.PlanePoint, timestampNs: Long): UInt =
        checkOpen().addCalibrationPoint(targetId, point, timestampNs)

    /** Forgets the gaze calibration (a new user). */
    public fun resetGazeCalibration(): Unit = checkOpen().resetGazeCalibration()

    /** Frees the native tracker. Idempotent; the tracker is unusable afterwards. */
    override fun close() {
        if (!closed) {
            closed = true
            native.destroy()
        }
    }

    private fun checkOpen(): FfiFaceTracker {
        check(!closed) { "FaceTracker is closed" }
        return native
    }
}
