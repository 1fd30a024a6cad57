import { DataTable, Panel, formatDuration, type Column } from '../../ui';
import { query, stopsSchema, type StopsAnswer } from './api';
import { QueryProblem } from './QueryProblem';
import type { Range } from './range';
import { useQuery } from './useQuery';

type Stop = StopsAnswer['stops'][number];

/** The alarms that stopped machines in the range, most time lost first. */
export function StopsSection(props: {
  range: Range | null;
  tick: number;
  names: ReadonlyMap<string, string>;
}) {
  const { range, names } = props;
  const q = range ? query({ from: range.from, to: range.to }) : '';
  const stops = useQuery(stopsSchema, range ? `/api/history/stops${q}` : null, 'stop reasons', props.tick);
  const max = Math.max(1, ...(stops.data?.stops.map((s) => s.seconds) ?? []));
  const columns: Column<Stop>[] = [
    { key: 'alarm', label: 'Reason', render: (s) => s.alarm ?? <span className="ui-muted">(no text)</span> },
    {
      key: 'time',
      label: 'Time stopped',
      render: (s) => (
        <span className="history-stop-time">
          <span className="history-stop-bar" aria-hidden="true">
            <span style={{ width: `${(s.seconds / max) * 100}%` }} />
          </span>
          {formatDuration(s.seconds)}
        </span>
      ),
    },
    { key: 'count', label: 'Times', align: 'right', render: (s) => String(s.count) },
    {
      key: 'machines',
      label: 'Machines',
      render: (s) => s.machines.map((m) => names.get(m) ?? m).join(', '),
    },
  ];
  return (
    <Panel
      title="Top stop reasons"
      testId="history-stops"
      actions={
        range && (
          <a
            className="ui-button secondary history-csv"
            href={`/api/history/stops.csv${q}`}
            download="shopdeck-stops.csv"
          >
            Export CSV
          </a>
        )
      }
    >
      <QueryProblem q={stops} what="the stop reasons" />
      {stops.data && (
        <DataTable
          columns={columns}
          rows={stops.data.stops}
          rowKey={(s, i) => `${s.alarm ?? ''}-${i}`}
          empty="No alarm stopped a machine in this range."
          label="Stop reasons"
          testId="history-stops-table"
        />
      )}
    </Panel>
  );
}
