// What `npm start` prints (scripts/start.mjs): the build's ~100 lines of output summed up in one
// line, and one line saying whether the SQLite module (better-sqlite3, built by `npm install`)
// loads. Kept apart from start.mjs so that a test can check the wording without building.

/**
 * One line for a build that succeeded, from the build's own output (Vite's "✓ N modules
 * transformed", the PWA plugin's "precache N entries (S KiB)") and the time it took.
 * @param {string} output what `npm run build` printed
 * @param {number} ms how long it took
 * @returns {string}
 */
export function buildSummary(output, ms) {
  const modules = /✓\s+(\d+)\s+modules transformed/.exec(output)?.[1];
  const precache = /precache\s+(\d+)\s+entries\s+\(([\d.]+\s*[KMG]i?B)\)/.exec(output);
  const parts = [];
  if (modules) parts.push(`${modules} modules`);
  if (precache) parts.push(`${precache[1]} files, ${precache[2].replace(/\s+/, ' ')}`);
  const secs = ms < 10_000 ? (ms / 1000).toFixed(1) : String(Math.round(ms / 1000));
  return `Built the console in ${secs} s${parts.length ? ` (${parts.join('; ')})` : ''}.`;
}

/**
 * Whether the SQLite module loads, in one line: the history and the audit log live in SQLite.
 * @param {() => { version: string }} load opens an in-memory database, returns the module's version
 * @returns {{ ok: boolean, line: string }}
 */
export function sqliteLine(load) {
  try {
    const { version } = load();
    return { ok: true, line: `SQLite module loads (better-sqlite3 ${version}).` };
  } catch (e) {
    const msg = (e instanceof Error ? e.message : String(e)).split('\n')[0];
    return {
      ok: false,
      line:
        `The SQLite module (better-sqlite3) does not load: ${msg}. ` +
        'Run `npm rebuild better-sqlite3` (it needs python3, make and a C++ compiler where no prebuilt binary exists).',
    };
  }
}
