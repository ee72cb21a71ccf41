import SwiftUI

/// Runs the SDK's shared benchmark (`runBenchmark`, the code behind the desktop `monotrack bench`)
/// on the bundled images and shows the per-stage tables of the thesis' Tables 4.4/4.5 (median, p90,
/// mean in ms) with the tracking vs re-detect cost per frame.
@main
struct BenchApp: App {
    var body: some Scene {
        WindowGroup { BenchView() }
    }
}
