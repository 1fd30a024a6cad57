import { useMemo, useState } from 'react';
import { useStore } from 'zustand';
import { fleetStore } from '../../fleet/fleet';
import { useCan } from '../../fleet/react';
import { Button, Panel, formatDateTime } from '../../ui';
import { infoSchema } from './api';
import { HistorySettings } from './HistorySettings';
import { JobsSection } from './JobsSection';
import { QueryProblem } from './QueryProblem';
import { localDate, resolveRange, type RangeChoice } from './range';
import { RangePicker } from './RangePicker';
import { ShiftReportSection } from './ShiftReportSection';
import { StopsSection } from './StopsSection';
import { TimelineSection } from './TimelineSection';
import { UtilisationSection } from './UtilisationSection';
import { useQuery } from './useQuery';
import { usePageTitle } from '../router';
import './history.css';

/**
 * `/history`: what the gateway recorded of every machine the user may use (issue 18): jobs, a
 * timeline per machine, utilisation, stop reasons and shift reports; the settings for supervisors.
 */
export function HistoryPage() {
  usePageTitle('History');
  const fleet = useStore(fleetStore, (s) => s.machines);
  const isSupervisor = useCan('supervisor');
  const [choice, setChoice] = useState<RangeChoice>({ kind: 'today' });
  // The range is worked out when it is picked or refreshed, so "today" does not move under a reader.
  const [now, setNow] = useState(() => Date.now());
  const [tick, setTick] = useState(0);
  const info = useQuery(infoSchema, '/api/history/info', 'history', tick);
  const shifts = useMemo(() => info.data?.shifts ?? [], [info.data]);
  const resolved = useMemo(() => resolveRange(choice, now, shifts), [choice, now, shifts]);
  const range = 'error' in resolved ? null : resolved;
  const machines = useMemo(() => fleet.map((m) => ({ id: m.id, name: m.name })), [fleet]);
  const names = useMemo(() => new Map(machines.map((m) => [m.id, m.name])), [machines]);
  const families = useMemo(() => [...new Set(fleet.map((m) => m.kind as string))].sort(), [fleet]);
  const refresh = () => {
    setNow(Date.now());
    setTick((t) => t + 1);
  };
  const pick = (c: RangeChoice) => {
    setChoice(c);
    setNow(Date.now());
  };
  const today = localDate(now);

  return (
    <div className="history-page" data-testid="history-page">
      <Panel
        title="Production history"
        level={1}
        actions={
          <Button onClick={refresh} data-testid="history-refresh">
            Refresh
          </Button>
        }
      >
        <RangePicker
          choice={choice}
          onChange={pick}
          shifts={shifts}
          today={today}
          error={'error' in resolved ? resolved.error : null}
        />
        {range && (
          <p className="ui-muted small" data-testid="history-range-shown">
            {formatDateTime(range.from)} to {formatDateTime(range.to)}
          </p>
        )}
        <QueryProblem q={info} what="the history" />
      </Panel>
      <TimelineSection range={range} tick={tick} now={now} />
      <UtilisationSection range={range} tick={tick} />
      <JobsSection range={range} tick={tick} machines={machines} families={families} />
      <StopsSection range={range} tick={tick} names={names} />
      <ShiftReportSection shifts={shifts} now={now} tick={tick} />
      {isSupervisor && <HistorySettings info={info.data} onSaved={refresh} />}
    </div>
  );
}
