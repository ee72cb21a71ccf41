package io.monotrack.bench

import android.content.ClipData
import android.content.ClipboardManager
import android.content.Intent
import android.graphics.Bitmap
import android.graphics.BitmapFactory
import android.os.Build
import android.os.Bundle
import android.util.Log
import android.widget.Button
import android.widget.RadioGroup
import android.widget.TextView
import android.widget.Toast
import androidx.appcompat.app.AppCompatActivity
import io.monotrack.MonotrackException
import io.monotrack.android.rgbaFrame
import io.monotrack.runBenchmark
import io.monotrack.sdkVersion
import java.io.IOException
import java.util.concurrent.ExecutorService
import java.util.concurrent.Executors

/**
 * Runs the SDK's shared benchmark (`runBenchmark`, the code behind the desktop `monotrack bench`) on
 * every image bundled from `samples/data` and shows, per image, the per-stage table of the thesis'
 * Tables 4.4/4.5 (median, p90, mean in ms) and the per-frame totals of the tracking and re-detect
 * paths with their ratio ([BenchSummary]).
 *
 * The benchmark runs on one background thread. The finished report is selectable text, can be copied
 * or shared as plain text, and is written to Logcat line by line under the tag [TAG]
 * (`adb logcat -s monotrack-bench`), so results can be collected from many devices.
 */
class BenchActivity : AppCompatActivity() {
    private val worker: ExecutorService = Executors.newSingleThreadExecutor()
    private lateinit var reportView: TextView
    private lateinit var iterations: RadioGroup
    private lateinit var run: Button
    private lateinit var copy: Button
    private lateinit var share: Button

    /** The last finished report, "" before the first run; kept across activity recreation. */
    private var report = ""

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        setContentView(R.layout.activity_bench)
        reportView = findViewById(R.id.report)
        iterations = findViewById(R.id.iterations)
        run = findViewById(R.id.run)
        copy = findViewById(R.id.copy)
        share = findViewById(R.id.share)

        report = savedInstanceState?.getString(KEY_REPORT).orEmpty()
        reportView.text = report
        run.setOnClickListener { start() }
        copy.setOnClickListener { copyReport() }
        share.setOnClickListener { shareReport() }
        setRunning(false)
    }

    override fun onSaveInstanceState(outState: Bundle) {
        super.onSaveInstanceState(outState)
        outState.putString(KEY_REPORT, report)
    }

    override fun onDestroy() {
        super.onDestroy()
        // A running benchmark cannot be interrupted (native code); it finishes and its result is dropped.
        worker.shutdown()
    }

    private fun start() {
        val n = selectedIterations()
        setRunning(true)
        reportView.text = getString(R.string.running, n.toInt())
        worker.execute {
            val text = try {
                benchmarkAll(n)
            } catch (e: LinkageError) {
                // JNA found no libmonotrack_ffi.so for this ABI (the native build was skipped): an
                // UnsatisfiedLinkError, wrapped in ExceptionInInitializerError by the first call.
                "cannot load the monotrack native library: ${e.cause?.message ?: e.message ?: e}\n"
            }
            text.lineSequence().filter { it.isNotEmpty() }.forEach { Log.i(TAG, it) }
            runOnUiThread {
                if (isDestroyed) return@runOnUiThread
                report = text
                reportView.text = text
                setRunning(false)
            }
        }
    }

    /** Benchmarks every bundled image with [iterations] frames per path. Runs on [worker]. */
    private fun benchmarkAll(iterations: UInt): String {
        val sb = StringBuilder()
        sb.append("monotrack ${sdkVersion()}, ${deviceDescription()}\n\n")
        val images = try {
            bundledImages()
        } catch (e: IOException) {
            return sb.append("cannot list the bundled images: ${e.message}\n").toString()
        }
        if (images.isEmpty()) sb.append("no bundled images\n\n")
        for (name in images) {
            sb.append(benchmarkImage(name, iterations)).append('\n')
        }
        sb.append(BenchSummary.thesisLine()).append('\n')
        return sb.toString()
    }

    /**
     * Decodes asset [name] (ARGB_8888, which Android stores as R, G, B, A bytes), copies it into a
     * direct buffer with the bitmap's row stride (`Bitmap.rgbaFrame()`) and runs the benchmark on it.
     * Returns the image's report block, or a line saying why it could not run.
     */
    private fun benchmarkImage(name: String, iterations: UInt): String {
        return try {
            val bitmap = assets.open(name).use { BitmapFactory.decodeStream(it, null, decodeOptions()) }
                ?: return "$name: cannot decode the image\n"
            val frame = try {
                bitmap.rgbaFrame()
            } finally {
                bitmap.recycle()
            }
            val result = runBenchmark(frame.bytes, frame.desc, iterations)
            BenchSummary.imageBlock(name, frame.desc.width.toInt(), frame.desc.height.toInt(), result)
        } catch (e: MonotrackException) {
            "$name: ${BenchSummary.describe(e)}\n"
        } catch (e: IOException) {
            "$name: cannot read: ${e.message}\n"
        }
    }

    /** The JPEG and PNG files at the root of the assets (`samples/data`, see build.gradle.kts), sorted. */
    private fun bundledImages(): List<String> =
        assets.list("").orEmpty()
            .filter { name -> IMAGE_EXTENSIONS.any { name.lowercase().endsWith(it) } }
            .sorted()

    private fun decodeOptions() = BitmapFactory.Options().apply {
        inPreferredConfig = Bitmap.Config.ARGB_8888
        inScaled = false
    }

    /** Manufacturer, model, chip (API 31+), primary ABI and Android version. */
    private fun deviceDescription(): String {
        val soc = if (Build.VERSION.SDK_INT >= Build.VERSION_CODES.S) " (${Build.SOC_MANUFACTURER} ${Build.SOC_MODEL})" else ""
        val abi = Build.SUPPORTED_ABIS.firstOrNull() ?: "unknown ABI"
        return "${Build.MANUFACTURER} ${Build.MODEL}$soc, $abi, Android ${Build.VERSION.RELEASE} (API ${Build.VERSION.SDK_INT})"
    }

    private fun selectedIterations(): UInt = when (iterations.checkedRadioButtonId) {
        R.id.iterations_10 -> 10u
        R.id.iterations_1000 -> 1000u
        else -> DEFAULT_ITERATIONS
    }

    private fun setRunning(running: Boolean) {
        run.isEnabled = !running
        for (i in 0 until iterations.childCount) iterations.getChildAt(i).isEnabled = !running
        copy.isEnabled = !running && report.isNotEmpty()
        share.isEnabled = !running && report.isNotEmpty()
    }

    private fun copyReport() {
        val clipboard = getSystemService(ClipboardManager::class.java) ?: return
        clipboard.setPrimaryClip(ClipData.newPlainText(getString(R.string.app_name), report))
        // Android 13+ shows its own confirmation for clipboard writes.
        if (Build.VERSION.SDK_INT < Build.VERSION_CODES.TIRAMISU) {
            Toast.makeText(this, R.string.copied, Toast.LENGTH_SHORT).show()
        }
    }

    private fun shareReport() {
        val send = Intent(Intent.ACTION_SEND)
            .setType("text/plain")
            .putExtra(Intent.EXTRA_SUBJECT, getString(R.string.share_subject))
            .putExtra(Intent.EXTRA_TEXT, report)
        startActivity(Intent.createChooser(send, getString(R.string.share)))
    }

    private companion object {
        /** Logcat tag of the report lines. */
        const val TAG = "monotrack-bench"
        const val KEY_REPORT = "report"

        /**
         * Frames per path unless another count is picked: a p90 from 10 samples above it, and a run
         * of seconds even where a re-detect frame takes tens of milliseconds.
         */
        const val DEFAULT_ITERATIONS = 100u
        val IMAGE_EXTENSIONS = listOf(".jpg", ".jpeg", ".png")
    }
}
