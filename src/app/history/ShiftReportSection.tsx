import { useState } from 'react';
import { Field, Panel, ScrollRegion, formatDateTime, formatDuration } from '../../ui';
import { query, shiftReportSchema, type JobCounts, type Shift } from './api';
import { QueryProblem } from './QueryProblem';
import { currentShift, localDate } from './range';
import { ShareBar } from './UtilisationSection';
import { useQuery } from './useQuery';

const JOB_KEYS: Array<[keyof JobCounts, string]> = [
  ['finished', 'Finished'],
  ['cancelled', 'Cancelled'],
  ['failed', 'Failed'],
  ['unknown', 'Unknown'],
  ['inProgress', 'In progress'],
];

function pct(seconds: number, span: number): string {
  return span > 0 ? `${Math.round((seconds / span) * 100)}%` : '—';
}

/** One shift on one date (the server's local time): time per state and jobs per machine. */
export function ShiftReportSection(props: { shifts: readonly Shift[]; now: number; tick: number }) {
  // Until one is picked: the shift under way (a night shift that began yesterday counts).
  const auto = currentShift(props.shifts, props.now);
  const [pickedDate, setDate] = useState<string | null>(null);
  const [picked, setPicked] = useState<string | null>(null);
  const date = pickedDate ?? auto?.date ?? localDate(props.now);
  const shift = props.shifts.find((s) => s.name === (picked ?? auto?.shift)) ?? props.shifts[0];
  const q = shift && date ? query({ date, shift: shift.name }) : null;
  const report = useQuery(
    shiftReportSchema,
    q ? `/api/history/shift-report${q}` : null,
    'shift report',
    props.tick,
  );
  const r = report.data;
  return (
    <Panel
      title="Shift report"
      testId="history-shift"
      actions={
        q && (
          <a
            className="ui-button secondary history-csv"
            href={`/api/history/shift-report.csv${q}`}
            download={`shopdeck-shift-${date}.csv`}
            data-testid="history-shift-csv"
          >
            Export CSV
          </a>
        )
      }
    >
      <div className="history-filters">
        <Field label="Date">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              type="date"
              value={date}
              onChange={(e) => setDate(e.target.value)}
            />
          )}
        </Field>
        <Field label="Shift">
          {(id) => (
            <select
              id={id}
              className="ui-input"
              value={shift?.name ?? ''}
              onChange={(e) => setPicked(e.target.value)}
              data-testid="history-shift-pick"
            >
              {props.shifts.map((s) => (
                <option key={s.name} value={s.name}>
                  {s.name} ({s.start}–{s.end})
                </option>
              ))}
            </select>
          )}
        </Field>
      </div>
      {props.shifts.length === 0 && (
        <p className="ui-muted">No shifts are set (a supervisor sets them below).</p>
      )}
      <QueryProblem q={report} what="the shift report" />
      {r && (
        <>
          <p className="ui-muted small">
            {r.shift.name}: {formatDateTime(r.from)} to {formatDateTime(r.to)}
            {r.spanS === 0
              ? ': not begun yet'
              : r.spanS * 1000 < r.to - r.from && `, counted up to now (${formatDuration(r.spanS)})`}
          </p>
          <ScrollRegion className="history-table-wrap" label="Shift report">
            <table className="history-util history-shift-table">
              <thead>
                <tr>
                  <th scope="col">Machine</th>
                  <th scope="col" className="history-util-bar-col">
                    Time
                  </th>
                  <th scope="col" className="num">
                    Running
                  </th>
                  <th scope="col" className="num">
                    Alarm
                  </th>
                  {JOB_KEYS.map(([k, w]) => (
                    <th key={k} scope="col" className="num">
                      {w}
                    </th>
                  ))}
                </tr>
              </thead>
              <tbody>
                {r.machines.map((m) => (
                  <tr key={m.machine} data-testid={`history-shift-${m.machine}`}>
                    <th scope="row" className="history-machine">
                      {m.machineName}
                    </th>
                    <td className="history-util-bar-col">
                      <ShareBar seconds={m.seconds} spanS={r.spanS} label={m.machineName} />
                    </td>
                    <td className="num">
                      {pct(m.seconds.running, r.spanS)}
                      <span className="ui-muted history-dur">{formatDuration(m.seconds.running)}</span>
                    </td>
                    <td className="num">
                      {pct(m.seconds.alarm, r.spanS)}
                      <span className="ui-muted history-dur">{formatDuration(m.seconds.alarm)}</span>
                    </td>
                    {JOB_KEYS.map(([k]) => (
                      <td key={k} className="num">
                        {m.jobs[k]}
                      </td>
                    ))}
                  </tr>
                ))}
              </tbody>
              <tfoot>
                <tr>
                  <th scope="row">All machines</th>
                  <td className="history-util-bar-col">
                    <ShareBar
                      seconds={r.totals.seconds}
                      spanS={r.spanS * Math.max(1, r.machines.length)}
                      label="All machines"
                    />
                  </td>
                  <td className="num">
                    {pct(r.totals.seconds.running, r.spanS * r.machines.length)}
                    <span className="ui-muted history-dur">{formatDuration(r.totals.seconds.running)}</span>
                  </td>
                  <td className="num">
                    {pct(r.totals.seconds.alarm, r.spanS * r.machines.length)}
                    <span className="ui-muted history-dur">{formatDuration(r.totals.seconds.alarm)}</span>
                  </td>
                  {JOB_KEYS.map(([k]) => (
                    <td key={k} className="num" data-testid={`history-shift-total-${k}`}>
                      {r.totals.jobs[k]}
                    </td>
                  ))}
                </tr>
              </tfoot>
            </table>
          </ScrollRegion>
        </>
      )}
    </Panel>
  );
}
