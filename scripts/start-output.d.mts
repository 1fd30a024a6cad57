/** Types of scripts/start-output.mjs (plain JavaScript: `npm start` runs before tsx is loaded). */
export function buildSummary(output: string, ms: number): string;
export function sqliteLine(load: () => { version: string }): { ok: boolean; line: string };
