/** Sample G-code for the simulator's uploads (the names are the fixture's uploads-list.json). */
export function sampleGcode(name: string, layers = 12): string {
  const lines: string[] = [`; ${name} — simulated file`, 'M140 S60', 'M104 S215', 'G28', 'G1 Z0.2 F3000'];
  let e = 0;
  const size = name.includes('cube') ? 20 : name.includes('first_layer') ? 80 : 40;
  const cx = 117.5;
  const cy = 98.25;
  for (let l = 0; l < (name.includes('first_layer') ? 1 : layers); l++) {
    lines.push(`; layer ${l + 1}`, `G1 Z${(0.2 + l * 0.2).toFixed(2)}`);
    for (let r = 0; r < 8; r++) {
      const h = size / 2 - r;
      const pts: Array<[number, number]> = [
        [cx - h, cy - h],
        [cx + h, cy - h],
        [cx + h, cy + h],
        [cx - h, cy + h],
        [cx - h, cy - h],
      ];
      for (const [x, y] of pts) {
        e += 0.4;
        lines.push(`G1 X${x.toFixed(2)} Y${y.toFixed(2)} E${e.toFixed(3)} F1800`);
      }
    }
  }
  lines.push('M104 S0', 'M140 S0', 'G1 Z20');
  return `${lines.join('\n')}\n`;
}

export interface GcodeWord {
  letter: string;
  value: number;
}

export function parseLine(line: string): { code: string; words: Map<string, number> } | null {
  const t = line.replace(/;.*$/, '').trim().toUpperCase();
  if (!t) return null;
  const parts = t.split(/\s+/);
  const code = parts[0] ?? '';
  const words = new Map<string, number>();
  for (const p of parts.slice(1)) {
    const v = Number(p.slice(1));
    if (p.length > 1 && Number.isFinite(v)) words.set(p[0] as string, v);
  }
  return { code, words };
}
