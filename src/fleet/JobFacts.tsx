import { KeyValues, ProgressBar } from '../ui';
import { useJobWords } from './job-facts';
import type { JobSummary } from './types';

/**
 * A machine page's job facts: name, progress, running time and time left, the same record and
 * the same words as the tile, the wall and the kiosk (job-facts.ts). Nothing while no job runs.
 * `extra`: the family's own rows after them (a layer, a line, the firmware's own estimates).
 */
export function JobFacts(props: {
  machine: string;
  job: JobSummary | null;
  bar?: boolean;
  extra?: Array<[string, React.ReactNode]>;
}) {
  const w = useJobWords(props.machine, props.job);
  if (!props.job || !w) return null;
  return (
    <div data-testid="job-facts">
      {props.bar !== false && <ProgressBar value={w.fraction} label="Job progress" />}
      <KeyValues
        items={[
          ['Job', <span data-testid="job-facts-name">{w.name}</span>],
          ['Progress', <span data-testid="job-facts-percent">{w.percent}</span>],
          ['Running', <span data-testid="job-facts-running">{w.runningFor}</span>],
          ['Remaining', <span data-testid="job-facts-remaining">{w.remaining}</span>],
          ...(props.extra ?? []),
        ]}
      />
    </div>
  );
}
