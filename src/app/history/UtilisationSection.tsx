import { Panel, ScrollRegion, formatDuration } from '../../ui';
import { query, utilisationSchema, type StateSeconds } from './api';
import { KIND_WORDS, shares } from './layout';
import { QueryProblem } from './QueryProblem';
import type { Range } from './range';
import { useQuery } from './useQuery';

/** A stacked bar of the states' shares; each part says its share and time when pointed at. */
export function ShareBar(props: { seconds: StateSeconds; spanS: number; label: string }) {
  const parts = shares(props.seconds, props.spanS).filter((s) => s.fraction > 0);
  return (
    <div
      className="history-share"
      role="img"
      aria-label={`${props.label}: ${parts.map((p) => `${KIND_WORDS[p.key]} ${p.percent}%`).join(', ') || 'nothing'}`}
    >
      {parts.map((p) => (
        <span
          key={p.key}
          className={`seg-${p.key}`}
          style={{ width: `${p.fraction * 100}%` }}
          title={`${KIND_WORDS[p.key]}: ${p.percent}% (${formatDuration(p.seconds)})`}
        />
      ))}
    </div>
  );
}

const NUMBERS = ['running', 'paused', 'idle', 'alarm', 'offline'] as const;

/** Per machine, how the range was spent (counted up to now). */
export function UtilisationSection(props: { range: Range | null; tick: number }) {
  const { range } = props;
  const q = range ? query({ from: range.from, to: range.to }) : '';
  const util = useQuery(
    utilisationSchema,
    range ? `/api/history/utilisation${q}` : null,
    'utilisation',
    props.tick,
  );
  const data = util.data;
  return (
    <Panel
      title="Utilisation"
      testId="history-utilisation"
      actions={
        range && (
          <a
            className="ui-button secondary history-csv"
            href={`/api/history/utilisation.csv${q}`}
            download="shopdeck-utilisation.csv"
          >
            Export CSV
          </a>
        )
      }
    >
      <QueryProblem q={util} what="the utilisation" />
      {data && data.spanS === 0 && <p className="ui-muted">This range has not begun yet.</p>}
      {data && data.spanS > 0 && (
        <ScrollRegion className="history-table-wrap" label="Utilisation">
          <table className="history-util">
            <caption className="ui-muted">Share of {formatDuration(data.spanS)}, up to now</caption>
            <thead>
              <tr>
                <th scope="col">Machine</th>
                <th scope="col" className="history-util-bar-col">
                  Share
                </th>
                {NUMBERS.map((k) => (
                  <th key={k} scope="col" className="num">
                    {KIND_WORDS[k]}
                  </th>
                ))}
              </tr>
            </thead>
            <tbody>
              {data.machines.map((m) => {
                const s = shares(m.seconds, data.spanS);
                return (
                  <tr key={m.machine} data-testid={`history-util-${m.machine}`}>
                    <th scope="row" className="history-machine">
                      {m.machineName}
                    </th>
                    <td className="history-util-bar-col">
                      <ShareBar seconds={m.seconds} spanS={data.spanS} label={m.machineName} />
                    </td>
                    {NUMBERS.map((k) => {
                      const p = s.find((x) => x.key === k);
                      return (
                        <td key={k} className="num">
                          <span className="history-pct">{p?.percent ?? 0}%</span>
                          <span className="ui-muted history-dur">{formatDuration(m.seconds[k])}</span>
                        </td>
                      );
                    })}
                  </tr>
                );
              })}
            </tbody>
          </table>
        </ScrollRegion>
      )}
    </Panel>
  );
}
