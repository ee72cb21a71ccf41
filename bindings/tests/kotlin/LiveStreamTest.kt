// JVM tests of the live-stream mode (the generated LiveFaceTracker and the Android wrapper
// io.monotrack.android.LiveTracker) and of the intrinsics convention, against the host library.
package io.monotrack.tests

import io.monotrack.CameraIntrinsics
import io.monotrack.FaceTracker
import io.monotrack.FrameDesc
import io.monotrack.HeadPose
import io.monotrack.MonotrackException
import io.monotrack.PixelFormat
import io.monotrack.PlanePoint
import io.monotrack.RunningMode
import io.monotrack.android.LiveEvent
import io.monotrack.android.LiveTracker
import io.monotrack.defaultTrackerConfig
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

class LiveStreamTest {
    private fun facePose(bytes: ByteArray, w: Int, h: Int, rot: Int, mirrored: Boolean, k: CameraIntrinsics): HeadPose {
        FaceTracker(defaultTrackerConfig().copy(runningMode = RunningMode.IMAGE, camera = k)).use { t ->
            val r = t.processImage(directOf(bytes), grayDesc(w, h, rot, mirrored))
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
        val tracker = LiveTracker(defaultTrackerConfig()) { e ->
            events.add(e)
            Thread.sleep(15) // a slow consumer: the camera outpaces it
            if (e.timestampNs == submitted * 1_000_000) last.countDown()
        }
        tracker.use {
            var replaced = 0
            val frame = directOf(u)
            for (i in 1..submitted) {
                if (it.process(frame, grayDesc(w, h), i * 1_000_000)) replaced++
                Thread.sleep(2)
            }
            assertTrue(last.await(60, TimeUnit.SECONDS), "the newest frame is always delivered")
            val list = synchronized(events) { events.toList() }
            val ts = list.map { e -> e.timestampNs }
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
    fun closeWhileBusyStopsDeliveriesAndLaterFramesAreRefused() {
        val (w, h, u) = upright
        val count = java.util.concurrent.atomic.AtomicInteger()
        val tracker = LiveTracker(defaultTrackerConfig()) { count.incrementAndGet() }
        tracker.process(directOf(u), grayDesc(w, h), 1)
        tracker.process(directOf(u), grayDesc(w, h), 2)
        tracker.close()
        val atClose = count.get()
        assertTrue(atClose <= 2)
        Thread.sleep(300)
        assertEquals(atClose, count.get(), "no delivery after close returns")
        tracker.close()
        assertThrows(IllegalStateException::class.java) { tracker.process(directOf(u), grayDesc(w, h), 3) }
    }

    @Test
    fun badFramesThrowAtOnceAndAThrowingListenerDoesNotStopTheStream() {
        val (w, h, u) = upright
        val seen = Collections.synchronizedList(mutableListOf<Long>())
        val second = CountDownLatch(1)
        LiveTracker(defaultTrackerConfig()) { e ->
            seen.add(e.timestampNs)
            if (e.timestampNs == 20L) second.countDown()
            if (e.timestampNs == 10L) throw IllegalStateException("the app's bug")
        }.use { t ->
            assertThrows(MonotrackException.InvalidFrame::class.java) {
                t.process(directOf(ByteArray(10)), grayDesc(w, h), 5)
            }
            t.process(directOf(u), grayDesc(w, h), 10)
            Thread.sleep(500)
            t.process(directOf(u), grayDesc(w, h), 20)
            assertTrue(second.await(60, TimeUnit.SECONDS), "events after the listener threw")
            assertEquals(10L, seen.first())
        }
    }

    @Test
    fun eventsFlowToCollectors() = runBlocking {
        val (w, h, u) = upright
        LiveTracker(defaultTrackerConfig()).use { t ->
            val first = async(Dispatchers.Default, start = CoroutineStart.UNDISPATCHED) {
                withTimeout(60_000) { t.events.first() }
            }
            t.process(directOf(u), grayDesc(w, h), 7)
            val e = first.await()
            assertEquals(7L, e.timestampNs)
            assertTrue(e is LiveEvent.Faces && e.result.faces.size == 1)
        }
    }

    @Test
    fun tapsCalibrateTheLiveTrackerAndUnusableOnesReachTheListenerAsFailures() {
        val (w, h, u) = upright
        val events = java.util.concurrent.LinkedBlockingQueue<LiveEvent>()
        LiveTracker(defaultTrackerConfig()) { events.add(it) }.use { t ->
            t.setGazeTargets(listOf(screenTarget("phone", 70.0, 150.0, 35.0, -8.0)))
            t.process(directOf(u), grayDesc(w, h), 10_000_000L)
            assertTrue(events.poll(60, TimeUnit.SECONDS) is LiveEvent.Faces)
            assertThrows(MonotrackException.InvalidConfig::class.java) {
                t.addCalibrationPoint("tv", PlanePoint(35.0, 50.0), 10_000_000L)
            }
            t.addCalibrationPoint("phone", PlanePoint(35.0, 50.0), 12_000_000L)
            t.process(directOf(u), grayDesc(w, h), 43_000_000L)
            val after = events.poll(60, TimeUnit.SECONDS)
            assertTrue(after is LiveEvent.Faces, "$after")
            val hit = (after as LiveEvent.Faces).result.faces.single().pointOfGaze!!.target!!
            assertTrue(hit.hit && abs(hit.point.uMm - 35.0) < 10.0 && abs(hit.point.vMm - 50.0) < 10.0, "$hit")
            // No face near this tap's time: the listener hears it, then the frame's faces.
            t.addCalibrationPoint("phone", PlanePoint(35.0, 50.0), 900_000_000L)
            t.process(directOf(u), grayDesc(w, h), 950_000_000L)
            val failed = events.poll(60, TimeUnit.SECONDS)
            assertTrue(failed is LiveEvent.Failed && failed.timestampNs == 900_000_000L, "$failed")
            assertTrue((failed as LiveEvent.Failed).error is MonotrackException.InvalidFrame)
            assertTrue(events.poll(60, TimeUnit.SECONDS) is LiveEvent.Faces)
        }
    }
}
