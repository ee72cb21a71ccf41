import Monotrack
import SwiftUI
import UIKit

struct BenchView: View {
    @State private var report = ""
    @State private var running = false

    /// Tracked frames per image: enough for a stable p90 (≥ 10 samples above it) in a few seconds.
    private static let iterations: UInt32 = 200
    private static let imageExtensions = ["jpg", "jpeg", "png"]

    var body: some View {
        VStack(alignment: .leading, spacing: 12) {
            Button(running ? "Running…" : "Run benchmark") { run() }
                .buttonStyle(.borderedProminent)
                .disabled(running)
            ScrollView {
                Text(report)
                    .font(.system(.footnote, design: .monospaced))
                    .textSelection(.enabled)
                    .frame(maxWidth: .infinity, alignment: .leading)
            }
        }
        .padding()
    }

    private func run() {
        running = true
        report = ""
        DispatchQueue.global(qos: .userInitiated).async {
            let text = Self.benchmarkAll()
            DispatchQueue.main.async {
                report = text
                running = false
            }
        }
    }

    private static func benchmarkAll() -> String {
        let device = UIDevice.current
        var out = "monotrack \(sdkVersion()) on \(machineIdentifier()) (\(device.systemName) \(device.systemVersion))\n\n"
        let urls = imageExtensions
            .flatMap { Bundle.main.urls(forResourcesWithExtension: $0, subdirectory: nil) ?? [] }
            .sorted { $0.lastPathComponent < $1.lastPathComponent }
        if urls.isEmpty { out += "no bundled images\n" }
        for url in urls {
            do {
                let (bytes, desc) = try rgbaFrame(url: url)
                let r = try runBenchmark(bytes: bytes, desc: desc, iterations: iterations)
                out += "\(url.lastPathComponent) \(desc.width)x\(desc.height), \(r.iterations) iterations (\(r.device))\n"
                out += r.table + "\n"
            } catch {
                out += "\(url.lastPathComponent): \(error)\n"
            }
        }
        return out
    }

    /// Decodes an image and draws it into a tightly packed RGBA buffer (premultiplied alpha is
    /// harmless: photos are opaque).
    private static func rgbaFrame(url: URL) throws -> (Data, FrameDesc) {
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

    /// The hardware model ("iPhone15,2"), which names the chip unlike `UIDevice.model`.
    private static func machineIdentifier() -> String {
        var info = utsname()
        uname(&info)
        return withUnsafeBytes(of: &info.machine) { raw in
            String(decoding: raw.prefix { $0 != 0 }, as: UTF8.self)
        }
    }
}
