import SwiftUI

/// Runs the SDK's benchmark (the desktop bench's code, through `runBenchmark`) on the bundled images
/// and shows the per-stage table: stage, median ms, p90 ms (thesis Tables 4.4/4.5 style).
@main
struct BenchApp: App {
    var body: some Scene {
        WindowGroup { BenchView() }
    }
}
