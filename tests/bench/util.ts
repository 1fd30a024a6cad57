/** Benchmark helpers: medians over repeated runs, printed as one JSON line per result. */
export function median(xs: number[]): number {
  const s = [...xs].sort((a, b) => a - b);
  const m = Math.floor(s.length / 2);
  return s.length % 2 ? (s[m] as number) : ((s[m - 1] as number) + (s[m] as number)) / 2;
}

export function measure(runs: number, fn: () => void): { median_ms: number; p90_ms: number; runs: number } {
  const times: number[] = [];
  for (let i = 0; i < Math.min(5, runs); i++) fn(); // warm-up
  for (let i = 0; i < runs; i++) {
    const t0 = performance.now();
    fn();
    times.push(performance.now() - t0);
  }
  const sorted = [...times].sort((a, b) => a - b);
  return {
    median_ms: round(median(times)),
    p90_ms: round(sorted[Math.floor(sorted.length * 0.9)] ?? 0),
    runs,
  };
}

export function round(n: number, digits = 4): number {
  const f = 10 ** digits;
  return Math.round(n * f) / f;
}

export function report(result: Record<string, unknown> & { name: string }): void {
  process.stdout.write(`${JSON.stringify(result)}\n`);
}

export function heapMiB(): number {
  const g = (globalThis as { gc?: () => void }).gc;
  g?.();
  return round(process.memoryUsage().heapUsed / 2 ** 20, 2);
}
