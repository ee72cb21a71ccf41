// Pure Kotlin (no android.* imports): the live-stream mode's idiomatic listener, tested on the JVM.
package io.monotrack.android

import io.monotrack.LiveStreamListener
import io.monotrack.LiveStreamResult
import io.monotrack.MonotrackException
import io.monotrack.TrackingResult
import kotlinx.coroutines.channels.BufferOverflow
import kotlinx.coroutines.flow.MutableSharedFlow
import kotlinx.coroutines.flow.SharedFlow
import kotlinx.coroutines.flow.asSharedFlow

/** What a live-stream [io.monotrack.FaceTracker] delivers for one frame. */
public sealed interface LiveEvent {
    /** The timestamp the frame was submitted with, milliseconds. */
    public val timestampMs: Long

    /** Frames skipped since the previous event because the tracker was busy. */
    public val framesDropped: Long

    /** The frame's faces. */
    public data class Faces(val live: LiveStreamResult) : LiveEvent {
        override val timestampMs: Long get() = live.timestampMs
        override val framesDropped: Long get() = live.framesDropped.toLong()

        /** The faces, in the upright image's pixels. */
        val result: TrackingResult get() = live.result
    }

    /** Tracking this frame failed, or a tap at this time could not be used; the stream goes on. */
    public data class Failed(
        override val timestampMs: Long,
        override val framesDropped: Long,
        val error: MonotrackException,
    ) : LiveEvent
}

/**
 * The listener of a live-stream tracker (MediaPipe's result listener) as Kotlin likes it: every
 * result or failure as a [LiveEvent], to [onEvent] when given and on [events].
 *
 * ```
 * val live = LiveEvents()
 * val tracker = FaceTracker(FaceTrackerOptions(runningMode = RunningMode.LIVE_STREAM), live) // off the main thread
 * scope.launch { live.events.collect { e -> if (e is LiveEvent.Faces) overlay.show(e.result) } }
 * analysis.setAnalyzer(executor) { image -> image.use { tracker.detectAsync(it, mirrored = true) } }
 * // on stop: tracker.close()
 * ```
 *
 * Events come on the tracker's worker thread, in timestamp order: post them to the UI thread and
 * return. An exception thrown by [onEvent] is caught by the SDK and does not stop the stream.
 *
 * @param onEvent called with every event, on the worker thread; `null` to use [events] only.
 */
public class LiveEvents(private val onEvent: ((LiveEvent) -> Unit)? = null) : LiveStreamListener {
    private val flow = MutableSharedFlow<LiveEvent>(
        extraBufferCapacity = EVENT_BUFFER,
        onBufferOverflow = BufferOverflow.DROP_OLDEST,
    )

    /**
     * Every event, for collectors subscribed when it happens (a hot flow: no replay). A collector
     * slower than the camera loses the oldest events, never blocks the tracker.
     */
    public val events: SharedFlow<LiveEvent> = flow.asSharedFlow()

    override fun onResult(result: LiveStreamResult): Unit = deliver(LiveEvent.Faces(result))

    override fun onError(timestampMs: Long, framesDropped: ULong, error: MonotrackException): Unit =
        deliver(LiveEvent.Failed(timestampMs, framesDropped.toLong(), error))

    private fun deliver(event: LiveEvent) {
        flow.tryEmit(event)
        onEvent?.invoke(event)
    }

    private companion object {
        const val EVENT_BUFFER = 8
    }
}
