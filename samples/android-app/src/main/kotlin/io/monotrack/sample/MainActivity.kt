package io.monotrack.sample

import android.Manifest
import android.content.pm.PackageManager
import android.os.Bundle
import android.util.Log
import android.widget.TextView
import androidx.activity.result.contract.ActivityResultContracts
import androidx.appcompat.app.AppCompatActivity
import androidx.appcompat.widget.SwitchCompat
import androidx.camera.core.CameraSelector
import androidx.camera.core.ImageAnalysis
import androidx.camera.core.ImageProxy
import androidx.camera.core.Preview
import androidx.camera.core.resolutionselector.ResolutionSelector
import androidx.camera.core.resolutionselector.ResolutionStrategy
import androidx.camera.lifecycle.ProcessCameraProvider
import androidx.camera.view.PreviewView
import androidx.core.content.ContextCompat
import io.monotrack.MonotrackException
import io.monotrack.FaceTracker
import io.monotrack.FaceTrackerOptions
import io.monotrack.RunningMode
import io.monotrack.android.detectForVideo
import io.monotrack.android.monotrackIntrinsics
import java.io.File
import java.util.concurrent.ExecutorService
import java.util.concurrent.Executors
import java.util.concurrent.TimeUnit

/**
 * Front camera preview with the tracker's results drawn on top. The tracker runs on CameraX's
 * analysis executor (one thread), only ever on the newest frame (STRATEGY_KEEP_ONLY_LATEST), so a
 * slow frame drops frames instead of queueing latency. The record switch writes what the tracker
 * is given to the app's files dir (`recordings/`), for `monotrack replay` on a desktop.
 */
class MainActivity : AppCompatActivity() {
    private lateinit var previewView: PreviewView
    private lateinit var overlay: OverlayView
    private lateinit var status: TextView
    private lateinit var record: SwitchCompat
    private lateinit var analysisExecutor: ExecutorService
    @Volatile
    private var tracker: FaceTracker? = null
    private val fps = FpsMeter()

    private val requestCamera = registerForActivityResult(ActivityResultContracts.RequestPermission()) { granted ->
        if (granted) startCamera() else status.setText(R.string.camera_denied)
    }

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        setContentView(R.layout.activity_main)
        previewView = findViewById(R.id.preview)
        overlay = findViewById(R.id.overlay)
        status = findViewById(R.id.status)
        record = findViewById(R.id.record)
        analysisExecutor = Executors.newSingleThreadExecutor()
        // Enabled once the tracker exists; the switch's calls run on the analysis thread, between
        // frames (they open and flush a file).
        record.isEnabled = false
        record.setOnCheckedChangeListener { _, on -> analysisExecutor.execute { setRecording(on) } }

        if (ContextCompat.checkSelfPermission(this, Manifest.permission.CAMERA) == PackageManager.PERMISSION_GRANTED) {
            startCamera()
        } else {
            requestCamera.launch(Manifest.permission.CAMERA)
        }
    }

    private fun startCamera() {
        val providerFuture = ProcessCameraProvider.getInstance(this)
        providerFuture.addListener({
            val provider = providerFuture.get()
            val front = provider.hasCamera(CameraSelector.DEFAULT_FRONT_CAMERA)
            val selector = if (front) CameraSelector.DEFAULT_FRONT_CAMERA else CameraSelector.DEFAULT_BACK_CAMERA

            val preview = Preview.Builder().build().also { it.setSurfaceProvider(previewView.surfaceProvider) }
            val analysis = ImageAnalysis.Builder()
                .setResolutionSelector(
                    ResolutionSelector.Builder()
                        // 640x480 is plenty for faces at arm's length and keeps the frame cheap.
                        .setResolutionStrategy(
                            ResolutionStrategy(ANALYSIS_SIZE, ResolutionStrategy.FALLBACK_RULE_CLOSEST_HIGHER_THEN_LOWER),
                        )
                        .build(),
                )
                .setBackpressureStrategy(ImageAnalysis.STRATEGY_KEEP_ONLY_LATEST)
                .setOutputImageFormat(ImageAnalysis.OUTPUT_IMAGE_FORMAT_YUV_420_888)
                .build()
            provider.unbindAll()
            val camera = provider.bindToLifecycle(this, selector, preview, analysis)
            // The analysis buffer's size as delivered (before rotation): what the intrinsics are for.
            val size = analysis.resolutionInfo?.resolution ?: ANALYSIS_SIZE
            val intrinsics = camera.cameraInfo.monotrackIntrinsics(size.width, size.height)
            // Loading the models takes a while: never on the main thread. The analyzer is set once
            // the tracker exists; until then CameraX drops the frames.
            analysisExecutor.execute {
                val tracker = try {
                    FaceTracker(FaceTrackerOptions(runningMode = RunningMode.VIDEO, camera = intrinsics))
                } catch (e: MonotrackException) {
                    runOnUiThread { status.text = getString(R.string.tracker_failed, e.message) }
                    return@execute
                }
                this.tracker = tracker
                runOnUiThread { record.isEnabled = true }
                analysis.setAnalyzer(analysisExecutor) { image -> analyze(tracker, image, front) }
            }
        }, ContextCompat.getMainExecutor(this))
    }

    private fun analyze(tracker: FaceTracker, image: ImageProxy, front: Boolean) {
        image.use {
            try {
                // The front preview is mirrored; mirror the results the same way.
                val result = tracker.detectForVideo(it, mirrored = front)
                val rate = fps.tick(System.nanoTime())
                overlay.post { overlay.show(result, rate) }
            } catch (e: MonotrackException.InvalidTimestamp) {
                // The camera restarted and its clock went back: start the tracks again.
                tracker.reset()
            } catch (e: MonotrackException) {
                // Every error the SDK raises, a caught internal fault included: skip the frame.
                Log.w(TAG, "frame skipped", e)
            } catch (e: IllegalStateException) {
                // The tracker was closed while this frame was in flight (activity finishing).
            }
        }
    }

    /** Starts a recording into a new file of the files dir, or stops the one running. */
    private fun setRecording(on: Boolean) {
        val tracker = tracker ?: return
        try {
            if (on && !tracker.isRecording()) {
                val dir = File(filesDir, "recordings").also { it.mkdirs() }
                val file = File(dir, "monotrack-${System.currentTimeMillis()}.mtrec")
                tracker.startRecording(file.path, MAX_RECORDING_BYTES)
                runOnUiThread { status.text = getString(R.string.recording_to, file.name) }
            } else if (!on && tracker.isRecording()) {
                val s = tracker.stopRecording()
                val note = if (s.truncated) getString(R.string.recording_truncated) else ""
                runOnUiThread {
                    status.text = getString(R.string.recording_saved, s.frames.toLong(), s.bytes.toLong() / 1e6, note)
                }
            }
        } catch (e: MonotrackException) {
            runOnUiThread {
                status.text = getString(R.string.recording_failed, e.message)
                record.isChecked = false
            }
        }
    }

    override fun onDestroy() {
        super.onDestroy()
        // Let the in-flight frame finish before freeing the native tracker it is using.
        analysisExecutor.shutdown()
        analysisExecutor.awaitTermination(EXECUTOR_DRAIN_MS, TimeUnit.MILLISECONDS)
        // Closing ends a running recording too, its file complete.
        tracker?.close()
        tracker = null
    }

    private companion object {
        const val TAG = "monotrack"
        val ANALYSIS_SIZE = android.util.Size(640, 480)

        /** A recording's limit: about half a minute of 640x480 NV21 frames at 30 fps. */
        val MAX_RECORDING_BYTES = 512UL shl 20

        /** Longer than any frame takes; the executor only ever holds one. */
        const val EXECUTOR_DRAIN_MS = 500L
    }
}

/** Frames per second as an exponential moving average of frame intervals. */
class FpsMeter {
    private var lastNs = 0L
    private var avgIntervalNs = 0.0

    /** Records a frame at [nowNs] and returns the smoothed rate (0 until two frames were seen). */
    fun tick(nowNs: Long): Double {
        if (lastNs != 0L) {
            val dt = (nowNs - lastNs).toDouble()
            avgIntervalNs = if (avgIntervalNs == 0.0) dt else avgIntervalNs + SMOOTHING * (dt - avgIntervalNs)
        }
        lastNs = nowNs
        return if (avgIntervalNs > 0.0) NS_PER_S / avgIntervalNs else 0.0
    }

    private companion object {
        /** Weight of the newest interval: about a 10-frame memory, steady yet responsive. */
        const val SMOOTHING = 0.1
        const val NS_PER_S = 1e9
    }
}
