// JVM tests of recording through the generated bindings: a video tracker and a live stream record
// NV21 frames of the sample face (a phone's sensor buffers, turned by 90°) to files, which
// bindings/tests/run-kotlin.sh then replays with `monotrack replay` (every frame must be identical);
// the recorder's typed errors and its size limit.
package io.monotrack.tests

import io.monotrack.FaceTracker
import io.monotrack.FaceTrackerOptions
import io.monotrack.FrameDesc
import io.monotrack.MonotrackException
import io.monotrack.PixelFormat
import io.monotrack.PlanePoint
import io.monotrack.RunningMode
import io.monotrack.android.LiveEvent
import io.monotrack.android.LiveEvents
import io.monotrack.screenTarget
import java.io.File
import java.nio.ByteBuffer
import java.util.Collections
import java.util.concurrent.CountDownLatch
import java.util.concurrent.TimeUnit
import javax.imageio.ImageIO
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertFalse
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

private val root = File(System.getProperty("monotrack.root") ?: ".")

/** Where the recordings go: run-kotlin.sh names the folder it replays from. */
private val recordings: File =
    File(System.getProperty("monotrack.recordings") ?: System.getProperty("java.io.tmpdir")).also { it.mkdirs() }

private const val PAD = 24

/**
 * Frame `i` of a clip of the sample face moving right by 6 px a frame, as the NV21 buffer of a
 * sensor mounted at 90° (rows padded, chroma grey): the frame's rotation 90 makes it upright.
 */
private class Clip {
    private val img = ImageIO.read(File(root, "samples/data/astronaut.jpg"))
    private val w = img.width
    private val h = img.height
    private val luma = IntArray(w * h) { k ->
        val p = img.getRGB(k % w, k / w)
        (77 * ((p shr 16) and 0xff) + 150 * ((p shr 8) and 0xff) + 29 * (p and 0xff) + 128) shr 8
    }

    /** The sensor buffer is h wide and w high; its pixel (x, y) is the upright (w - 1 - y, x). */
    val desc = FrameDesc(h.toUInt(), w.toUInt(), PixelFormat.NV21, (h + PAD).toUInt(), (h + PAD).toUInt(), 2u, 90u, false)

    fun frame(i: Int): ByteBuffer {
        val stride = h + PAD
        val bytes = ByteArray(stride * w + stride * ((w + 1) / 2)) { 128.toByte() }
        for (y in 0 until w) for (x in 0 until h) {
            val ux = w - 1 - y - 6 * i
            bytes[y * stride + x] = (if (ux in 0 until w) luma[x * w + ux] else 128).toByte()
        }
        return ByteBuffer.allocateDirect(bytes.size).put(bytes).also { it.rewind() }
    }
}

class RecordingTest {
    @Test
    fun aVideoTrackerRecordsItsFramesTargetsAndTaps() {
        val clip = Clip()
        val file = File(recordings, "kotlin-video.mtrec")
        FaceTracker(FaceTrackerOptions(runningMode = RunningMode.VIDEO)).use { t ->
            assertFalse(t.isRecording())
            assertThrows(MonotrackException.InvalidState::class.java) { t.stopRecording() }
            t.setGazeTargets(listOf(screenTarget("phone", 70.0, 150.0, 35.0, -8.0)))
            t.detectForVideo(clip.frame(0), clip.desc, 0L)
            t.startRecording(file.path, 64UL shl 20)
            assertTrue(t.isRecording())
            assertThrows(MonotrackException.InvalidState::class.java) { t.startRecording(file.path, 64UL shl 20) }
            for (i in 1..5) {
                val r = t.detectForVideo(clip.frame(i), clip.desc, 33L * i)
                assertEquals(1, r.faces.size, "frame $i")
                if (i == 3) assertEquals(1u, t.addCalibrationPoint("phone", PlanePoint(35.0, 50.0), 33L * i))
            }
            val s = t.stopRecording()
            assertFalse(t.isRecording())
            assertEquals(5UL, s.frames)
            assertEquals(0UL, s.droppedFrames)
            assertFalse(s.truncated)
            assertEquals(file.length().toULong(), s.bytes)
        }
    }

    @Test
    fun aLiveStreamRecordsTheFramesItTookAndNotesItsDrops() {
        val clip = Clip()
        val file = File(recordings, "kotlin-live.mtrec")
        val events = Collections.synchronizedList(mutableListOf<LiveEvent>())
        val submitted = 8L
        val last = CountDownLatch(1)
        val listener = LiveEvents { e ->
            events.add(e)
            if (e.timestampMs == 33L * submitted) last.countDown()
        }
        val frames = (1..submitted.toInt()).map { clip.frame(it) }
        FaceTracker(FaceTrackerOptions(runningMode = RunningMode.LIVE_STREAM), listener).use { t ->
            t.startRecording(file.path, 64UL shl 20)
            for (i in 1..submitted) {
                t.detectAsync(frames[(i - 1).toInt()], clip.desc, 33L * i)
                Thread.sleep(20) // faster than the worker: it takes some frames and drops others
            }
            assertTrue(last.await(120, TimeUnit.SECONDS), "the newest frame is always delivered")
            val s = t.stopRecording()
            val list = synchronized(events) { events.toList() }
            assertTrue(list.all { it is LiveEvent.Faces }, "$list")
            assertEquals(list.size.toULong(), s.frames, "the frames the worker took")
            assertEquals(list.sumOf { it.framesDropped }.toULong(), s.droppedFrames)
            assertEquals(submitted.toULong(), s.frames + s.droppedFrames)
            assertTrue(s.frames >= 2UL, "the first frame and the last are taken: $s")
            assertEquals(file.length().toULong(), s.bytes)
        }
    }

    @Test
    fun aRecordingStopsAtItsSizeLimitAndBadPathsAreTyped() {
        val clip = Clip()
        val file = File(recordings, "kotlin-small.mtrec")
        FaceTracker(FaceTrackerOptions(runningMode = RunningMode.VIDEO)).use { t ->
            assertThrows(MonotrackException.Io::class.java) { t.startRecording("/nonexistent-dir/x.mtrec", 1UL shl 20) }
            assertThrows(MonotrackException.InvalidConfig::class.java) { t.startRecording(file.path, 100UL) }
            // Room for the settings and about one frame.
            val oneFrame = clip.frame(0).capacity().toLong()
            t.startRecording(file.path, (oneFrame + 20_000).toULong())
            for (i in 0..3) t.detectForVideo(clip.frame(i), clip.desc, 33L * i)
            val s = t.stopRecording()
            assertTrue(s.truncated)
            assertEquals(1UL, s.frames)
            assertTrue(file.length() <= oneFrame + 20_000)
        }
    }
}
