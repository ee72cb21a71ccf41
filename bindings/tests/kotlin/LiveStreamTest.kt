// JVM tests of the live-stream mode (the generated FaceTracker in LIVE_STREAM with the Android
// listener io.monotrack.android.LiveEvents) and of the intrinsics convention, against the host library.
package io.monotrack.tests

import io.monotrack.CameraIntrinsics
import io.monotrack.FaceTracker
import io.monotrack.FaceTrackerOptions
import io.monotrack.FrameDesc
import io.monotrack.HeadPose
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
import kotlin.math.abs
import kotlinx.coroutines.CoroutineStart
import kotlinx.coroutines.Dispatchers
import kotlinx.coroutines.async
import kotlinx.coroutines.flow.first
import kotlinx.coroutines.runBlocking
import kotlinx.coroutines.withTimeout
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Assertions.assertTrue
import org.junit.jupiter.api.Test

private val repo = File(System.getProperty("monotrack.root") ?: ".")

/** The sample face as upright 8-bit luma, cropped to a landscape 512×400. */
private val upright: Triple<Int, Int, ByteArray> by lazy {
    val img = ImageIO.read(File(repo, "samples/data/astronaut.jpg"))
    val (w, h) = 512 to 400
    val out = ByteArray(w * h)
    for (y in 0 until h) for (x in 0 until w) {
        val p = img.getRGB(x, y + 40)
        val l = (77 * ((p shr 16) and 0xff) + 150 * ((p shr 8) and 0xff) + 29 * (p and 0xff) + 128) shr 8
        out[y * w + x] = l.toByte()
    }
    Triple(w, h, out)
}

private fun directOf(bytes: ByteArray): ByteBuffer = ByteBuffer.allocateDirect(bytes.size).put(bytes).also { it.rewind() }

private fun grayDesc(w: Int, h: Int, rot: Int = 0, mirrored: Boolean = false) =
    FrameDesc(w.toUInt(), h.toUInt(), PixelFormat.GRAY8, w.toUInt(), 0u, 0u, rot.toUInt(), mirrored)

/** The sensor buffer that turning by [rot] then mirroring makes into the upright picture. */
private fun sensorBuffer(rot: Int, mirrored: Boolean): Triple<Int, Int, ByteArray> {
    val (uw, uh, u) = upright
    val (bw, bh) = if (rot % 180 == 90) uh to uw else uw to uh
    val b = ByteArray(bw * bh)
    for (oy in 0 until uh) for (ox in 0 until uw) {
        val cx = if (mirrored) uw - 1 - ox else ox
        val (x, y) = when (rot) {
            0 -> cx to oy
            90 -> oy to (bh - 1 - cx)
            180 -> (bw - 1 - cx) to (bh - 1 - oy)
            else -> (bw - 1 - oy) to cx
        }
        b[y * bw + x] = u[oy * uw + ox]
    }
    return Triple(bw, bh, b)
}

/** Intrinsics of a [w]×[h] image turned clockwise by [rot] (as the SDK documents the turn). */
private fun turned(k: CameraIntrinsics, w: Int, h: Int, rot: Int): CameraIntrinsics = when (rot) {
    0 -> k
    90 -> CameraIntrinsics(k.fy, k.fx, h - k.cy, k.cx)
    180 -> CameraIntrinsics(k.fx, k.fy, w - k.cx, h - k.cy)
    else -> CameraIntrinsics(k.fy, k.fx, k.cy, w - k.cx)
}

private val liveStream = FaceTrackerOptions(runningMode = RunningMode.LIVE_STREAM)

class LiveStreamTest {
    private fun facePose(bytes: ByteArray, w: Int, h: Int, rot: Int, mirrored: Boolean, k: CameraIntrinsics): HeadPose {
        FaceTracker(FaceTrackerOptions(camera = k)).use { t ->
            val r = t.detect(directOf(bytes), grayDesc(w, h, rot, mirrored))
            assertEquals(1, r.faces.size, "rotation $rot mirrored $mirrored")
            return r.faces[0].pose
        }
    }

    @Test
    fun sensorIntrinsicsGiveTheSamePoseInEveryOrientation() {
        val (uw, uh, u) = upright
        val ku = CameraIntrinsics(520.0, 545.0, 0.42 * uw, 0.58 * uh)
        val reference = facePose(u, uw, uh, 0, false, ku)
        for (rot in listOf(0, 90, 180, 270)) for (mirrored in listOf(false, true)) {
            val (bw, bh, b) = sensorBuffer(rot, mirrored)
            val m = if (mirrored) ku.copy(cx = uw - ku.cx) else ku
            val ks = turned(m, uw, uh, (360 - rot) % 360)
            val pose = facePose(b, bw, bh, rot, mirrored, ks)
            val t = listOf(pose.translationMm.x, pose.translationMm.y, pose.translationMm.z)
            val tr = listOf(reference.translationMm.x, reference.translationMm.y, reference.translationMm.z)
            for (i in 0 until 3) assertTrue(abs(t[i] - tr[i]) < 1e-3, "rot $rot mirrored $mirrored: t $t vs $tr")
            for (i in 0 until 9) assertTrue(abs(pose.rotation[i] - reference.rotation[i]) < 1e-6, "rot $rot mirrored $mirrored: R")
        }
    }

    @Test
    fun framesAreDroppedWhileBusyAndEventsStayInOrder() {
        val (w, h, u) = upright
        val events = Collections.synchronizedList(mutableListOf<LiveEvent>())
        val last = CountDownLatch(1)
        val submitted = 40L
        val listener = LiveEvents { e ->
            events.add(e)
            Thread.sleep(15) // a slow consumer: the camera outpaces it
            if (e.timestampMs == submitted) last.countDown()
        }
        FaceTracker(liveStream, listener).use {
            var replaced = 0
            val frame = directOf(u)
            for (i in 1..submitted) {
                if (it.detectAsync(frame, grayDesc(w, h), i)) replaced++
                Thread.sleep(2)
            }
            assertTrue(last.await(60, TimeUnit.SECONDS), "the newest frame is always delivered")
            val list = synchronized(events) { events.toList() }
            val ts = list.map { e -> e.timestampMs }
            assertEquals(ts.sorted(), ts, "in timestamp order")
            assertEquals(ts.distinct(), ts)
            assertTrue(list.all { e -> e is LiveEvent.Faces && e.result.faces.size == 1 }, "every event found the face")
            val dropped = list.sumOf { e -> e.framesDropped }
            assertEquals(replaced.toLong(), dropped, "each replaced frame counted once")
            assertEquals(submitted, list.size + dropped, "every frame delivered or counted dropped")
            assertTrue(dropped > 0, "a 15 ms consumer fed every 2 ms drops frames")
        }
    }

    @Test
    fun shutdownWhileBusyStopsDeliveriesAndLaterFramesAreRefused() {
        val (w, h, u) = upright
        val count = java.util.concurrent.atomic.AtomicInteger()
        FaceTracker(liveStream, LiveEvents { count.incrementAndGet() }).use { tracker ->
            tracker.detectAsync(directOf(u), grayDesc(w, h), 1)
            tracker.detectAsync(directOf(u), grayDesc(w, h), 2)
            tracker.shutdown()
            val atClose = count.get()
            assertTrue(atClose <= 2)
            Thread.sleep(300)
            assertEquals(atClose, count.get(), "no delivery after shutdown returns")
            tracker.shutdown()
            assertThrows(MonotrackException.InvalidState::class.java) { tracker.detectAsync(directOf(u), grayDesc(w, h), 3) }
        }
    }

    @Test
    fun aTimestampThatDoesNotIncreaseIsRefusedUntilReset() {
        val (w, h, u) = upright
        val events = java.util.concurrent.LinkedBlockingQueue<LiveEvent>()
        FaceTracker(liveStream, LiveEvents { events.add(it) }).use { t ->
            t.detectAsync(directOf(u), grayDesc(w, h), 100)
            assertTrue(events.poll(60, TimeUnit.SECONDS) is LiveEvent.Faces)
            assertThrows(MonotrackException.InvalidTimestamp::class.java) { t.detectAsync(directOf(u), grayDesc(w, h), 100) }
            assertThrows(MonotrackException.InvalidState::class.java) { t.detectForVideo(directOf(u), grayDesc(w, h), 101) }
            // A camera restart: reset, and time may start again.
            t.reset()
            t.detectAsync(directOf(u), grayDesc(w, h), 3)
            val e = events.poll(60, TimeUnit.SECONDS)
            assertTrue(e is LiveEvent.Faces && e.timestampMs == 3L, "$e")
        }
    }

    @Test
    fun badFramesThrowAtOnceAndAThrowingListenerDoesNotStopTheStream() {
        val (w, h, u) = upright
        val seen = Collections.synchronizedList(mutableListOf<Long>())
        val second = CountDownLatch(1)
        val listener = LiveEvents { e ->
            seen.add(e.timestampMs)
            if (e.timestampMs == 20L) second.countDown()
            if (e.timestampMs == 10L) throw IllegalStateException("the app's bug")
        }
        FaceTracker(liveStream, listener).use { t ->
            assertThrows(MonotrackException.InvalidFrame::class.java) {
                t.detectAsync(directOf(ByteArray(10)), grayDesc(w, h), 5)
            }
            t.detectAsync(directOf(u), grayDesc(w, h), 10)
            Thread.sleep(500)
            t.detectAsync(directOf(u), grayDesc(w, h), 20)
            assertTrue(second.await(60, TimeUnit.SECONDS), "events after the listener threw")
            assertEquals(10L, seen.first())
        }
    }

    @Test
    fun eventsFlowToCollectors() = runBlocking {
        val (w, h, u) = upright
        val listener = LiveEvents()
        FaceTracker(liveStream, listener).use { t ->
            val first = async(Dispatchers.Default, start = CoroutineStart.UNDISPATCHED) {
                withTimeout(60_000) { listener.events.first() }
            }
            t.detectAsync(directOf(u), grayDesc(w, h), 7)
            val e = first.await()
            assertEquals(7L, e.timestampMs)
            assertTrue(e is LiveEvent.Faces && e.result.faces.size == 1)
        }
    }

    @Test
    fun tapsCalibrateTheLiveTrackerAndUnusableOnesReachTheListenerAsFailures() {
        val (w, h, u) = upright
        val events = java.util.concurrent.LinkedBlockingQueue<LiveEvent>()
        FaceTracker(liveStream, LiveEvents { events.add(it) }).use { t ->
            t.setGazeTargets(listOf(screenTarget("phone", 70.0, 150.0, 35.0, -8.0)))
            t.detectAsync(directOf(u), grayDesc(w, h), 10L)
            assertTrue(events.poll(60, TimeUnit.SECONDS) is LiveEvent.Faces)
            assertThrows(MonotrackException.InvalidConfig::class.java) {
                t.addCalibrationPoint("tv", PlanePoint(35.0, 50.0), 10L)
            }
            // Learnt later, on the worker: no count yet.
            assertEquals(null, t.addCalibrationPoint("phone", PlanePoint(35.0, 50.0), 12L))
            t.detectAsync(directOf(u), grayDesc(w, h), 43L)
            val after = events.poll(60, TimeUnit.SECONDS)
            assertTrue(after is LiveEvent.Faces, "$after")
            val hit = (after as LiveEvent.Faces).result.faces.single().pointOfGaze!!.target!!
            assertTrue(hit.hit && abs(hit.point.uMm - 35.0) < 10.0 && abs(hit.point.vMm - 50.0) < 10.0, "$hit")
            // No face near this tap's time: the listener hears it, then the frame's faces.
            t.addCalibrationPoint("phone", PlanePoint(35.0, 50.0), 900L)
            t.detectAsync(directOf(u), grayDesc(w, h), 950L)
            val failed = events.poll(60, TimeUnit.SECONDS)
            assertTrue(failed is LiveEvent.Failed && failed.timestampMs == 900L, "$failed")
            assertTrue((failed as LiveEvent.Failed).error is MonotrackException.InvalidFrame)
            assertTrue(events.poll(60, TimeUnit.SECONDS) is LiveEvent.Faces)
        }
    }
}
