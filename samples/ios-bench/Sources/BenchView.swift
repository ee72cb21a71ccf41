import Monotrack
import SwiftUI
import UIKit

/// The benchmark screen: iteration count, run button, then per image a table for each path (stage,
/// median, p90, mean in ms) and the per-frame totals with their ratio; the toolbar copies the whole
/// report as text.
struct BenchView: View {
    @StateObject private var model = BenchModel()
    /// Frames per path.
    @State private var iterations: UInt32 = 100

    /// 100 by default: a p90 from 10 samples above it, and a run of seconds even where a re-detect
    /// frame takes tens of milliseconds.
    private static let iterationChoices: [UInt32] = [10, 100, 1000]

    var body: some View {
        NavigationView {
            List {
                Section {
                    Picker("Frames per path", selection: $iterations) {
                        ForEach(Self.iterationChoices, id: \.self) { Text("\($0)").tag($0) }
                    }
                    .pickerStyle(.segmented)
                    .disabled(model.running)
                    Button {
                        model.run(iterations: iterations)
                    } label: {
                        HStack {
                            Text(model.running ? "Running…" : "Run benchmark")
                            if model.running {
                                Spacer()
                                ProgressView()
                            }
                        }
                    }
                    .disabled(model.running)
                } footer: {
                    Text("Frames per path: each image is processed that many times tracked (video mode) and re-detected (image mode). Run the Release build.")
                }

                if !model.header.isEmpty {
                    Section {
                        Text(model.header).font(.footnote).textSelection(.enabled)
                        if model.results.isEmpty {
                            Text("No bundled images.").foregroundColor(.red)
                        }
                    } header: {
                        Text("Device")
                    }
                }

                ForEach(model.results) { result in
                    ImageSections(result: result)
                }

                if !model.results.isEmpty {
                    Section {
                        Text(BenchSummary.thesisLine()).font(.footnote)
                    } header: {
                        Text("For comparison")
                    }
                }
            }
            .listStyle(.grouped)
            .navigationTitle("monotrack bench")
            .navigationBarTitleDisplayMode(.inline)
            .toolbar {
                ToolbarItem(placement: .navigationBarTrailing) {
                    Button {
                        UIPasteboard.general.string = model.text
                    } label: {
                        Label("Copy report", systemImage: "doc.on.doc")
                    }
                    .disabled(model.header.isEmpty || model.running)
                }
            }
        }
        .navigationViewStyle(.stack)
    }
}

/// One image's results: a stage table per path and the per-frame totals, or why it failed.
private struct ImageSections: View {
    let result: ImageBench

    var body: some View {
        if let report = result.report {
            ForEach(BenchSummary.paths) { path in
                Section {
                    StageRow(name: "stage", values: ["median", "p90", "mean"]).foregroundColor(.secondary)
                    ForEach(BenchSummary.stages(report, path: path), id: \.name) { s in
                        StageRow(name: String(s.name.dropFirst(path.prefix.count + 1)),
                                 values: [s.medianUs, s.p90Us, s.meanUs].map { BenchSummary.ms($0) })
                    }
                } header: {
                    Text("\(result.name) \(result.width)×\(result.height) · \(path.title), ms")
                }
            }
            Section {
                if let t = BenchSummary.totals(report) {
                    TotalRow(label: "Tracking", value: String(format: "%.2f ms", t.trackingMs))
                    TotalRow(label: "Re-detect", value: String(format: "%.2f ms", t.redetectMs))
                    TotalRow(label: "Re-detect / tracking", value: t.ratio.map { String(format: "%.2f×", $0) } ?? "n/a")
                }
                if !BenchSummary.faceFound(report) {
                    Text("No face found: the landmark and fit stages did not run, so the paths are not comparable.")
                        .foregroundColor(.orange)
                }
            } header: {
                Text("\(result.name) · per frame (median), \(report.iterations) frames per path")
            } footer: {
                Text(report.device)
            }
        } else {
            Section {
                Text(result.failure ?? "failed").foregroundColor(.red)
            } header: {
                Text(result.name)
            }
        }
    }
}

/// A table row: the stage name, then three right-aligned number columns.
private struct StageRow: View {
    let name: String
    let values: [String]

    var body: some View {
        HStack(spacing: 4) {
            Text(name).lineLimit(1)
            Spacer(minLength: 4)
            ForEach(values.indices, id: \.self) { i in
                Text(values[i]).frame(width: 60, alignment: .trailing)
            }
        }
        .font(.system(.footnote, design: .monospaced))
    }
}

/// A label with its value on the right.
private struct TotalRow: View {
    let label: String
    let value: String

    var body: some View {
        HStack {
            Text(label)
            Spacer()
            Text(value).font(.system(.body, design: .monospaced))
        }
    }
}
