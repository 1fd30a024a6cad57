import type { StatsExport } from '../../../fleet/server-part';
import { statsSchema } from '../wire';

/**
 * TouchCut's stored days in the history's export (`GET /api/history/touchcut-stats.csv`): loaded
 * by the history's read workers (the TouchCut server part names this file), so kept small.
 */

type SessionTime =
  'activeTime' | 'productiveTime' | 'unproductiveTime' | 'errorTime' | 'idleTime' | 'toolOnTime';

export const statsExport: StatsExport = {
  columns: [
    'sessions',
    'active_s',
    'productive_s',
    'unproductive_s',
    'error_s',
    'idle_s',
    'tool_on_s',
    'programs',
    'errors',
  ],
  row(stats) {
    const s = statsSchema.safeParse(stats);
    const sum = (k: SessionTime) => (s.success ? s.data.sessions.reduce((a, x) => a + (x[k] ?? 0), 0) : null);
    return [
      s.success ? s.data.sessions.length : null,
      sum('activeTime'),
      sum('productiveTime'),
      sum('unproductiveTime'),
      sum('errorTime'),
      sum('idleTime'),
      sum('toolOnTime'),
      s.success ? s.data.programs.length : null,
      s.success ? s.data.errors.length : null,
    ];
  },
};
