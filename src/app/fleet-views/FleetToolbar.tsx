import './fleet-views.css';
import { useId, useSyncExternalStore } from 'react';
import { familyLabel } from '../../controllers';
import type { MachineInfo } from '../../fleet/types';
import { STATE_CLASS_WORDS } from './arrange';
import type { FleetPrefs } from './prefs';

const SORT_WORDS = {
  file: 'Machines file order',
  name: 'Name',
  state: 'State (alarms first)',
  family: 'Family',
};

const GROUP_WORDS = { none: 'No grouping', family: 'Family', group: 'Group (bay, room)' };

/** A labelled select of one preference: `options` maps each value to its words. */
function Choice<K extends 'sort' | 'state' | 'family' | 'groupBy'>(props: {
  name: K;
  label: string;
  options: Record<string, string>;
  prefs: FleetPrefs;
  update: (patch: Partial<FleetPrefs>) => void;
}) {
  const id = useId();
  const testId = `fleet-${props.name === 'groupBy' ? 'group' : props.name}`;
  return (
    <label className="fleet-field" htmlFor={id}>
      <span>{props.label}</span>
      <select
        id={id}
        className="ui-input"
        value={props.prefs[props.name]}
        // The value is one of the options; the preferences check it again (normalizePrefs).
        onChange={(e) => props.update({ [props.name]: e.target.value })}
        data-testid={testId}
      >
        {Object.entries(props.options).map(([value, words]) => (
          <option key={value} value={value}>
            {words}
          </option>
        ))}
      </select>
    </label>
  );
}

const COARSE = '(pointer: coarse)';

function subscribeCoarse(fn: () => void): () => void {
  if (typeof matchMedia !== 'function') return () => undefined;
  const q = matchMedia(COARSE);
  q.addEventListener('change', fn);
  return () => q.removeEventListener('change', fn);
}

/** A touch screen (a finger, not a mouse): the fleet's view controls fold into one. */
function useCoarsePointer(): boolean {
  return useSyncExternalStore(
    subscribeCoarse,
    () => typeof matchMedia === 'function' && matchMedia(COARSE).matches,
    () => false,
  );
}

/** The folded controls' button: the view in a few words ("Tiles · In alarm · by Name"). */
export function viewWords(prefs: FleetPrefs, families: Record<string, string>): string {
  const words = [prefs.view === 'grid' ? 'Tiles' : 'List'];
  if (prefs.state !== 'all') words.push(STATE_CLASS_WORDS[prefs.state]);
  if (prefs.family !== 'all') words.push(families[prefs.family] ?? prefs.family);
  if (prefs.q.trim()) words.push(`“${prefs.q.trim()}”`);
  if (prefs.sort !== 'file') words.push(`by ${SORT_WORDS[prefs.sort]}`);
  if (prefs.groupBy !== 'none') words.push(`grouped by ${GROUP_WORDS[prefs.groupBy]}`);
  return words.join(' · ');
}

/**
 * View, sort, filters and grouping of the fleet page. On a touch screen they fold into one "View"
 * control (a tablet's first screen is for the machines); how many machines a filter hides always
 * shows.
 */
export function FleetToolbar(props: {
  prefs: FleetPrefs;
  update: (patch: Partial<FleetPrefs>) => void;
  machines: readonly MachineInfo[];
  shown: number;
}) {
  const { prefs, update, machines } = props;
  const id = useId();
  const families: Record<string, string> = { all: 'All families' };
  // A family filter from a bookmark stays selectable even when no machine of it is left.
  for (const k of [...machines.map((m) => m.kind), prefs.family])
    if (k !== 'all') families[k] = familyLabel(k);
  const filtered = prefs.state !== 'all' || prefs.family !== 'all' || prefs.q.trim() !== '';
  const common = { prefs, update };
  const folded = useCoarsePointer();
  const controls = (
    <>
      <div className="fleet-view-switch" role="group" aria-label="View">
        {(['grid', 'list'] as const).map((v) => (
          <button
            key={v}
            type="button"
            className={`ui-button ${prefs.view === v ? 'primary' : 'secondary'}`}
            aria-pressed={prefs.view === v}
            onClick={() => update({ view: v })}
            data-testid={`view-${v}`}
          >
            {v === 'grid' ? 'Tiles' : 'List'}
          </button>
        ))}
      </div>
      <label className="fleet-field" htmlFor={id}>
        <span>Name</span>
        <input
          id={id}
          className="ui-input"
          type="search"
          placeholder="Filter by name"
          value={prefs.q}
          maxLength={80}
          onChange={(e) => update({ q: e.target.value })}
          data-testid="fleet-filter"
        />
      </label>
      <Choice name="state" label="State" options={{ all: 'All states', ...STATE_CLASS_WORDS }} {...common} />
      <Choice name="family" label="Family" options={families} {...common} />
      <Choice name="sort" label="Sort" options={SORT_WORDS} {...common} />
      <Choice name="groupBy" label="Group" options={GROUP_WORDS} {...common} />
    </>
  );
  return (
    <div
      className={`fleet-toolbar${folded ? ' folded' : ''}`}
      role="group"
      aria-label="Fleet view"
      data-testid="fleet-toolbar"
    >
      {folded ? (
        <details className="fleet-fold" data-testid="fleet-view-fold">
          <summary className="ui-button secondary">
            <span className="fleet-fold-label">View</span>
            <span className="fleet-fold-words">{viewWords(prefs, families)}</span>
          </summary>
          <div className="fleet-fold-body">{controls}</div>
        </details>
      ) : (
        controls
      )}
      {filtered && (
        <div className="fleet-shown small" role="status" data-testid="fleet-shown">
          {props.shown} of {machines.length} shown{' '}
          <button
            type="button"
            className="ui-button secondary"
            onClick={() => update({ state: 'all', family: 'all', q: '' })}
            data-testid="fleet-clear"
          >
            Show all
          </button>
        </div>
      )}
    </div>
  );
}
