// Pure Kotlin (no android.* imports): the live-stream mode's idiomatic face, tested on the JVM.
package io.monotrack.android

import io.monotrack.FrameDesc
import io.monotrack.LiveFaceTracker
import io.monotrack.LiveStreamListener
import io.monotrack.LiveStreamResult
import io.monotrack.MonotrackException
import io.monotrack.TrackerConfig
import io.monotrack.TrackingResult
import io.monotrack.defaultTrackerConfig
import kotlinx.coroutines.channels.BufferOverflow
import kotlinx.coroutines.flow.MutableSharedFlow
import kotlinx.coroutines.flow.SharedFlow
import kotlinx.coroutines.flow.asSharedFlow
import java.io.Closeable
import java.nio.ByteBuffer

/** What a [LiveTracker] delivers for one frame. */
public sealed interface LiveEvent {
    /** The timestamp the frame was submitted with. */
    public val timestampNs: Long

    /** Frames skipped since the previous event because the tracker was busy. */
    public val framesDropped: Long

    /** The frame's faces. */
    public data class Faces(val live: LiveStreamResult) : LiveEvent {
        override val timestampNs: Long get() = live.timestampNs
        override val framesDropped: Long get() = live.framesDropped.toLong()

        /** The faces, in the upright image's pixels. */
        val result: TrackingResult get() = live.result
    }

    /** Tracking this frame failed, or a tap at this time could not be used; the stream goes on. */
    public data class Failed(
        override val timestampNs: Long,
        override val framesDropped: Long,
        val error: MonotrackException,
    ) : LiveEvent
}

/**
 * The face tracker in live-stream mode (as MediaPipe's LIVE_STREAM): [process] copies the frame and
 * returns at once, one native worker thread tracks it, and the result arrives later as a
 * [LiveEvent] — to [listener] when given, and on [events]. While the worker is busy the newest frame
 * waits and replaces any older waiting one, so a slow phone skips frames instead of falling behind;
 * each event says how many were skipped.
 *
 * Events come on the worker thread, in timestamp order: post them to the UI thread and return.
 * An exception thrown by [listener] is caught by the SDK and does not stop the stream.
 *
 * ```
 * val tracker = LiveTracker(config)                  // build off the main thread: it loads models
 * scope.launch { tracker.events.collect { e -> if (e is LiveEvent.Faces) overlay.show(e.result) } }
 * analysis.setAnalyzer(executor) { image -> image.use { tracker.process(it, mirrored = true) } }
 * // on stop: tracker.close()
 * ```
 *
 * @param config tracker settings ([TrackerConfig.runningMode] is not read: a live stream tracks).
 * @param listener called with every event, on the worker thread; `null` to use [events] only.
 * @throws MonotrackException.InvalidConfig for out-of-range settings.
 * @throws MonotrackException.ModelLoad when the bundled models fail to load.
 */
public class LiveTracker(
    config: TrackerConfig = defaultTrackerConfig(),
    private val listener: ((LiveEvent) -> Unit)? = null,
) : Closeable {
    private val flow = MutableSharedFlow<LiveEvent>(
        extraBufferCapacity = EVENT_BUFFER,
        onBufferOverflow = BufferOverflow.DROP_OLDEST,
    )

    /**
     * Every event, for collectors subscribed when it happens (a hot flow: no replay). A collector
     * slower than the camera loses the oldest events, never blocks the tracker.
     */
    public val events: SharedFlow<LiveEvent> = flow.asSharedFlow()

    private val native = LiveFaceTracker(config, object : LiveStreamListener {
        override fun onResult(result: LiveStreamResult) = deliver(LiveEvent.Faces(result))

        override fun onError(timestampNs: Long, framesDropped: ULong, error: MonotrackException) =
            deliver(LiveEvent.Failed(timestampNs, framesDropped.toLong(), error))
    })
    private val timestamps = MonotonicTimestamps()

    @Volatile
    private var closed = false

    private fun deliver(event: LiveEvent) {
        flow.tryEmit(event)
        listener?.invoke(event)
    }

    /**
     * Submits one frame held in a direct [ByteBuffer] (any [io.monotrack.PixelFormat]) and returns
     * without waiting; the bytes are copied, so the buffer may be reused at once.
     *
     * @param timestampNs the frame's time; made strictly increasing here (see [MonotonicTimestamps]).
     * @return true when a frame still waiting was replaced by this one.
     * @throws MonotrackException.InvalidFrame when [bytes] does not match [desc].
     * @throws IllegalStateException after [close].
     */
    public fun process(bytes: ByteBuffer, desc: FrameDesc, timestampNs: Long): Boolean {
        check(!closed) { "LiveTracker is closed" }
        return native.processAsync(bytes, desc, timestamps.next(timestampNs))
    }

    /**
     * Sets the targets each face's point of gaze is located among (as `FaceTracker.setGazeTargets`);
     * frames from the next one on use them.
     *
     * @throws MonotrackException.InvalidConfig for a bad target or a repeated id.
     */
    public fun setGazeTargets(targets: List<io.monotrack.GazeTarget>) {
        check(!closed) { "LiveTracker is closed" }
        native.setGazeTargets(targets)
    }

    /**
     * A tap: the user looked at [point] on the target [targetId] at [timestampNs] (the frames'
     * clock). Learnt on the worker before the next frame; a tap it cannot use (no face within
     * 250 ms of it) arrives as [LiveEvent.Failed] with the tap's time.
     *
     * @throws MonotrackException.InvalidConfig for an unknown target, a non-finite point or the gaze
     *   output turned off.
     */
    public fun addCalibrationPoint(targetId: String, point: io.monotrack.PlanePoint, timestampNs: Long) {
        check(!closed) { "LiveTracker is closed" }
        native.addCalibrationPoint(targetId, point, timestampNs)
    }

    /** Forgets the tap calibration (a new user) before the next frame. */
    public fun resetGazeCalibration() {
        if (!closed) native.resetGazeCalibration()
    }

    /**
     * Stops the worker (a frame being tracked finishes and is delivered; a waiting one is dropped)
     * and frees the native tracker. Idempotent. Called from [listener], it returns at once and the
     * worker stops after that call.
     */
    override fun close() {
        if (!closed) {
            closed = true
            native.shutdown()
            native.close()
        }
    }

    private companion object {
        const val EVENT_BUFFER = 8
    }
}
