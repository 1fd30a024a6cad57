/**
 * A child process for alarms.test.ts (finding 15): an alarm centre on the data folder of
 * argv[2] that sees a flame, says "announced <id>" when the record is announced, and then hangs
 * in the listener (the parent kills it with SIGKILL: the snapshot timer never runs).
 */
import { AlarmCentre } from './alarms';
import { createLogger } from './log';

const dir = process.argv[2] ?? '';
const centre = new AlarmCentre({
  dataDir: dir,
  log: createLogger({ write: () => undefined }),
  onChange: (event, r) => {
    if (event !== 'alarm.raised') return;
    process.stdout.write(`announced ${r.id}\n`);
    // Hang here until killed: nothing else of this process runs after the announcement.
    const end = Date.now() + 30_000;
    while (Date.now() < end) {
      /* busy */
    }
  },
});
centre.observe(
  { id: 'laser-1', name: 'Laser 1', kind: 'xtool' },
  { state: 'running', alarm: null, job: 'a.gc', alarms: [] },
  {
    state: 'alarm',
    alarm: 'FLAME DETECTED',
    job: 'a.gc',
    alarms: [{ key: 'xtool-flame', severity: 'critical', text: 'FLAME DETECTED', blocking: true }],
  },
);
