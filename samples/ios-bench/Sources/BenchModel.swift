import Foundation
import Monotrack
import UIKit
import os

/// One bundled image's benchmark: its report, or why it could not run.
struct ImageBench: Identifiable {
    /// File name in the app bundle ("astronaut.jpg").
    let name: String
    /// Decoded size, pixels (0 when decoding failed).
    let width: Int
    let height: Int
    /// The SDK's report; nil when the image could not be decoded or benchmarked.
    let report: BenchReport?
    /// Why there is no report.
    let failure: String?

    var id: String { name }
}

/// Runs the shared benchmark on every bundled image off the main thread and publishes the results.
@MainActor
final class BenchModel: ObservableObject {
    /// SDK version and device of the last run; empty before the first run.
    @Published private(set) var header = ""
    /// One entry per bundled image, sorted by name.
    @Published private(set) var results: [ImageBench] = []
    @Published private(set) var running = false

    /// The last run as plain text, the same layout as the Android app's report: the header, one
    /// block per image (`BenchSummary.imageBlock`) and the thesis' figures.
    var text: String {
        var out = header + "\n\n"
        if results.isEmpty { out += "no bundled images\n\n" }
        for r in results {
            if let report = r.report {
                out += BenchSummary.imageBlock(image: r.name, width: r.width, height: r.height, report: report)
            } else {
                out += "\(r.name): \(r.failure ?? "failed")\n"
            }
            out += "\n"
        }
        return out + BenchSummary.thesisLine() + "\n"
    }

    /// Benchmarks every bundled image with `iterations` frames per path on a background task, then
    /// publishes the results and writes the report to the unified log. Ignored while a run is going.
    func run(iterations: UInt32) {
        guard !running else { return }
        running = true
        let device = UIDevice.current
        let header = "monotrack \(sdkVersion()), \(BenchRunner.machineIdentifier()), \(device.systemName) \(device.systemVersion)"
        Task {
            let results = await Task.detached(priority: .userInitiated) {
                BenchRunner.benchmarkBundledImages(iterations: iterations)
            }.value
            self.header = header
            self.results = results
            self.running = false
            BenchRunner.log(self.text)
        }
    }
}

/// The work of a run, free of UI state so it can run on any thread.
enum BenchRunner {
    private static let imageExtensions = ["jpg", "jpeg", "png"]
    private static let logger = Logger(subsystem: "io.monotrack.bench", category: "report")

    /// Benchmarks every JPEG and PNG in the app bundle (`samples/data`, see project.yml).
    static func benchmarkBundledImages(iterations: UInt32) -> [ImageBench] {
        imageExtensions
            .flatMap { Bundle.main.urls(forResourcesWithExtension: $0, subdirectory: nil) ?? [] }
            .sorted { $0.lastPathComponent < $1.lastPathComponent }
            .map { benchmark(url: $0, iterations: iterations) }
    }

    /// Decodes one image into RGBA bytes and runs `runBenchmark` on it; errors become `failure`.
    static func benchmark(url: URL, iterations: UInt32) -> ImageBench {
        let name = url.lastPathComponent
        do {
            let (bytes, desc) = try rgbaFrame(url: url)
            let report = try runBenchmark(bytes: bytes, desc: desc, iterations: iterations)
            return ImageBench(name: name, width: Int(desc.width), height: Int(desc.height), report: report, failure: nil)
        } catch {
            return ImageBench(name: name, width: 0, height: 0, report: nil, failure: BenchSummary.describe(error))
        }
    }

    /// Decodes an image (UIImage → CGImage) and draws it into a tightly packed RGBA buffer.
    /// Premultiplied alpha is harmless: photos are opaque. The EXIF orientation is not applied
    /// (`cgImage` is the stored pixels), which is right for the bundled images.
    static func rgbaFrame(url: URL) throws -> (Data, FrameDesc) {
        guard let image = UIImage(contentsOfFile: url.path)?.cgImage else {
            throw FrameError.invalidLayout("cannot decode \(url.lastPathComponent)")
        }
        let w = image.width, h = image.height, rowBytes = 4 * w
        var data = Data(count: rowBytes * h)
        let drawn = data.withUnsafeMutableBytes { raw -> Bool in
            guard let ctx = CGContext(data: raw.baseAddress, width: w, height: h, bitsPerComponent: 8,
                                      bytesPerRow: rowBytes, space: CGColorSpaceCreateDeviceRGB(),
                                      bitmapInfo: CGImageAlphaInfo.premultipliedLast.rawValue)
            else { return false }
            ctx.draw(image, in: CGRect(x: 0, y: 0, width: w, height: h))
            return true
        }
        guard drawn else { throw FrameError.invalidLayout("cannot create an RGBA context") }
        let desc = FrameDesc(width: UInt32(w), height: UInt32(h), format: .rgba8, rowStride: UInt32(rowBytes),
                             uvRowStride: 0, uvPixelStride: 0, rotationDegrees: 0, mirrored: false)
        return (data, desc)
    }

    /// The hardware model ("iPhone8,4" for an iPhone SE), which names the chip unlike `UIDevice.model`.
    static func machineIdentifier() -> String {
        var info = utsname()
        uname(&info)
        return withUnsafeBytes(of: &info.machine) { raw in
            String(decoding: raw.prefix { $0 != 0 }, as: UTF8.self)
        }
    }

    /// Writes `text` to the unified log line by line (Xcode's console, Console.app, `log stream
    /// --predicate 'subsystem == "io.monotrack.bench"'`), public so it is readable off the device.
    static func log(_ text: String) {
        for line in text.split(separator: "\n") {
            logger.info("\(String(line), privacy: .public)")
        }
    }
}
