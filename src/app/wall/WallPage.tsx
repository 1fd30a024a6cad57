import './wall.css';
import { memo, useEffect, useId, useMemo, useRef, useState } from 'react';
import { useStore } from 'zustand';
import { familyLabel } from '../../controllers';
import { authStore } from '../../fleet/auth';
import { linkWords } from '../../fleet/contract';
import { fleetStore, getRuntime, type MachineRuntime } from '../../fleet/fleet';
import { useDerived, useNow, useScheduler, useSnapshot } from '../../fleet/react';
import { mostSevereAlarm, type MachineInfo } from '../../fleet/types';
import { Badge, ProgressBar, formatTime } from '../../ui';
import { useJobWords } from '../../fleet/job-facts';
import { MachineAge } from '../Age';
import { cardFields, LINK_TONE, shownState } from '../status';
import { useRuntimesOf } from '../runtimes';
import { usePageTitle } from '../router';
import { alarmFeed, startAlarmFeed } from '../alarms/feed';
import { sessionExtra } from '../auth/api';
import {
  inAlarmForWall,
  nextSpotlight,
  serverAlarmsForWall,
  SPOTLIGHT_MS,
  spotlightNow,
  wallColumns,
  type WallAlarm,
} from './alarms';
import {
  useWallGrouping,
  wallSectionLayout,
  wallSections,
  type SectionPlace,
  type WallGrouping,
} from './prefs';

/**
 * The wall screen (`/wall`): the whole fleet for a TV, large type, read only — no links, no
 * buttons, no inputs, whoever is signed in. When machines are in alarm it shows them one after
 * the other, each for `SPOTLIGHT_MS`, beside the fleet; with none it shows the fleet alone.
 * Grouped by bay (`/wall?group=bay`, or the view control), one section per bay. The view control
 * is there only while someone is at the screen (a mouse moved, a key pressed): the TV's picture
 * has none.
 */
export function WallPage() {
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const signedOut = useStore(sessionExtra, (s) => s.signedOut);
  const { machines, status, error } = useStore(fleetStore);
  usePageTitle('Wall screen');
  if (mode === 'secured' && !user)
    return (
      <WallMessage>
        {signedOut ? 'Signed out — sign in again. ' : ''}The wall screen needs a signed-in session:{' '}
        <a href="/login?next=%2Fwall" data-testid="wall-sign-in">
          sign in
        </a>{' '}
        on this screen, then it shows the fleet.
      </WallMessage>
    );
  if (status === 'loading') return <WallMessage>Loading the fleet…</WallMessage>;
  if (status === 'error') return <WallMessage>{error}</WallMessage>;
  if (machines.length === 0) return <WallMessage>No machines.</WallMessage>;
  return <Wall machines={machines} />;
}

function WallMessage({ children }: { children: React.ReactNode }) {
  return (
    <main className="wall wall-message" data-testid="wall">
      <h1 className="sr-only">Wall screen</h1>
      <p>{children}</p>
    </main>
  );
}

function Wall({ machines }: { machines: MachineInfo[] }) {
  const { rts, sources } = useRuntimesOf(machines);
  // The machines in alarm, in fleet order; React hears of it only when that list changes.
  const localInAlarm = useDerived(
    sources,
    () => rts.filter((rt) => inAlarmForWall(rt.snapshot.getState().alarms)).map((rt) => rt.info.id),
    sameIds,
  );
  // And by the alarm centre's list (the server sees what no page watches).
  useEffect(() => startAlarmFeed(), []);
  const records = useStore(alarmFeed, (s) => s.records);
  // No answer yet, or the last read failed (401, error): the header says so, never "No alarms".
  const unreadable = useStore(alarmFeed, (s) => s.error !== null || s.records === null);
  const serverAlarms = useMemo(() => serverAlarmsForWall(records), [records]);
  const combined = useMemo(
    () => machines.filter((m) => localInAlarm.includes(m.id) || serverAlarms.has(m.id)).map((m) => m.id),
    [machines, localInAlarm, serverAlarms],
  );
  // The same machines are the same list: the spotlight's timer runs on while the list only changes
  // elsewhere (a new answer of the alarm list about other machines).
  const kept = useRef(combined);
  if (!sameIds(kept.current, combined)) kept.current = combined;
  const inAlarm = kept.current;
  const [chosen, setChosen] = useState<string | null>(null);
  const spot = spotlightNow(inAlarm, chosen);
  const scheduler = useScheduler();
  useEffect(() => {
    if (inAlarm.length === 0) return;
    return scheduler.every(SPOTLIGHT_MS, () =>
      setChosen((c) => nextSpotlight(inAlarm, spotlightNow(inAlarm, c))),
    );
  }, [inAlarm, scheduler]);
  const spotInfo = spot ? machines.find((m) => m.id === spot) : undefined;
  const [grouping, setGrouping] = useWallGrouping();
  const present = useSomeoneAtTheScreen();
  const aspect = spotInfo ? 0.8 : 1.9;
  const card = (m: MachineInfo, inSection: boolean) => (
    <WallCard
      key={m.id}
      info={m}
      highlighted={m.id === spotInfo?.id}
      server={serverAlarms.get(m.id)}
      inSection={inSection}
    />
  );
  return (
    <div className={`wall${spotInfo ? ' has-spotlight' : ''}`} data-testid="wall">
      <WallHeader
        total={machines.length}
        inAlarm={inAlarm.length}
        unreadable={unreadable}
        spot={spotInfo ? inAlarm.indexOf(spotInfo.id) : -1}
        view={present ? <WallView grouping={grouping} onChange={setGrouping} /> : null}
      />
      <main className="wall-body">
        <h1 className="sr-only">Wall screen</h1>
        {spotInfo && (
          <section
            className="wall-spotlight"
            data-testid="wall-spotlight"
            data-machine={spotInfo.id}
            aria-label={`In alarm: ${spotInfo.name}`}
          >
            <WallCard key={spotInfo.id} info={spotInfo} big server={serverAlarms.get(spotInfo.id)} />
          </section>
        )}
        {grouping === 'bay' ? (
          <BaySections machines={machines} aspect={aspect} card={card} />
        ) : (
          <FleetGrid machines={machines} aspect={aspect} card={card} />
        )}
      </main>
    </div>
  );
}

type CardOf = (m: MachineInfo, inSection: boolean) => React.ReactNode;

/** The fleet in one grid that fills the screen (or the part beside the machine in alarm) without scrolling. */
function FleetGrid({ machines, aspect, card }: { machines: MachineInfo[]; aspect: number; card: CardOf }) {
  const cols = wallColumns(machines.length, aspect);
  const rows = Math.ceil(machines.length / cols);
  return (
    <div
      className="wall-grid"
      style={{
        gridTemplateColumns: `repeat(${cols}, minmax(0, 1fr))`,
        gridTemplateRows: `repeat(${rows}, minmax(0, 1fr))`,
      }}
      data-testid="wall-grid"
    >
      {machines.map((m) => card(m, false))}
    </div>
  );
}

/**
 * One section per bay, its name whole as the heading, the machines without one last ("No bay"):
 * one grid for all (the sections share its columns, small bays side by side), still without
 * scrolling.
 */
function BaySections({ machines, aspect, card }: { machines: MachineInfo[]; aspect: number; card: CardOf }) {
  const sections = useMemo(() => wallSections(machines), [machines]);
  const layout = wallSectionLayout(
    sections.map((s) => s.machines.length),
    aspect,
  );
  return (
    <div
      className="wall-grid wall-sections"
      style={{
        gridTemplateColumns: `repeat(${layout.columns}, minmax(0, 1fr))`,
        gridTemplateRows: layout.rowsTemplate,
      }}
      data-testid="wall-grid"
    >
      {sections.map((s, i) => (
        <BaySection key={s.key} label={s.label} place={layout.places[i]}>
          {s.machines.map((m) => card(m, true))}
        </BaySection>
      ))}
    </div>
  );
}

function BaySection({
  label,
  place,
  children,
}: {
  label: string;
  place: SectionPlace | undefined;
  children: React.ReactNode;
}) {
  const id = useId();
  return (
    <section
      className="wall-section"
      style={
        place && {
          gridColumn: `${place.column} / span ${place.columns}`,
          gridRow: `${place.row} / span ${place.rows + 1}`,
        }
      }
      aria-labelledby={id}
      data-testid={`wall-section-${label}`}
    >
      <h2 className="wall-section-head" id={id}>
        {label}
      </h2>
      {children}
    </section>
  );
}

const GROUPING_WORDS: Record<WallGrouping, string> = { none: 'One grid', bay: 'By bay' };

/** The wall's one view control: shown while someone is at the screen, never focused by itself. */
function WallView({ grouping, onChange }: { grouping: WallGrouping; onChange: (g: WallGrouping) => void }) {
  return (
    <label className="wall-view">
      Group
      <select
        value={grouping}
        onChange={(e) => onChange(e.target.value === 'bay' ? 'bay' : 'none')}
        data-testid="wall-group"
      >
        {(Object.keys(GROUPING_WORDS) as WallGrouping[]).map((g) => (
          <option key={g} value={g}>
            {GROUPING_WORDS[g]}
          </option>
        ))}
      </select>
    </label>
  );
}

/** The view control stays this long after the last sign of someone at the screen. */
const PRESENT_MS = 15_000;

/**
 * Whether someone is at the wall's screen: a mouse moved (a real move: a browser's own zero-length
 * moves do not count), a touch, a key. For `PRESENT_MS` after the last, or while the view control
 * has the focus.
 */
function useSomeoneAtTheScreen(): boolean {
  const [present, setPresent] = useState(false);
  const scheduler = useScheduler();
  useEffect(() => {
    // One deadline that each sign of someone moves on (not a timer per pointer move).
    let lastSeen = 0;
    const away = scheduler.deadline({
      due: () => lastSeen + PRESENT_MS,
      fire: () => {
        if (document.activeElement?.closest('.wall-view')) arm();
        else setPresent(false);
      },
    });
    const arm = () => {
      lastSeen = scheduler.now();
      away.update();
    };
    const seen = () => {
      setPresent(true);
      arm();
    };
    const moved = (e: PointerEvent) => {
      if (e.pointerType !== 'mouse' || e.movementX !== 0 || e.movementY !== 0) seen();
    };
    window.addEventListener('pointermove', moved);
    window.addEventListener('pointerdown', seen);
    window.addEventListener('keydown', seen);
    return () => {
      window.removeEventListener('pointermove', moved);
      window.removeEventListener('pointerdown', seen);
      window.removeEventListener('keydown', seen);
      away.cancel();
    };
  }, [scheduler]);
  return present;
}

function WallHeader({
  total,
  inAlarm,
  spot,
  unreadable,
  view,
}: {
  total: number;
  inAlarm: number;
  spot: number;
  unreadable: boolean;
  view: React.ReactNode;
}) {
  const now = useNow(1000);
  return (
    <header className="wall-head">
      <span className="wall-brand">
        <img src="/favicon.svg" alt="" width={40} height={40} />
        Shopdeck
      </span>
      <span data-testid="wall-count">{total} machines</span>
      <span
        className={inAlarm > 0 || unreadable ? 'wall-alarm-count tone-bad' : 'wall-alarm-count'}
        data-testid="wall-alarm-count"
      >
        {inAlarm === 0
          ? unreadable
            ? 'Cannot read the alarms'
            : 'No alarms'
          : inAlarm === 1
            ? '1 in alarm'
            : `${inAlarm} in alarm`}
        {inAlarm > 1 && spot >= 0 && ` · showing ${spot + 1} of ${inAlarm}`}
        {inAlarm > 0 && unreadable && ' · cannot read the alarms'}
      </span>
      {view}
      <time className="wall-clock" data-testid="wall-clock">
        {formatTime(now)}
      </time>
    </header>
  );
}

const WallCard = memo(function WallCard(props: {
  info: MachineInfo;
  big?: boolean;
  highlighted?: boolean;
  /** The alarm centre's alarm of this machine (when this page's own view has none). */
  server?: WallAlarm | undefined;
  /** In its bay's section (whose heading names the bay). */
  inSection?: boolean;
}) {
  const rt = getRuntime(props.info.id);
  if (!rt) return null;
  return <WallCardBody {...props} rt={rt} />;
});

function WallCardBody({
  info,
  rt,
  big,
  highlighted,
  server,
  inSection,
}: {
  info: MachineInfo;
  rt: MachineRuntime;
  big?: boolean;
  highlighted?: boolean;
  server?: WallAlarm | undefined;
  inSection?: boolean;
}) {
  const s = useSnapshot(rt, cardFields);
  // The job in the words of every view: the server's record first (fleet/job-facts.ts).
  const job = useJobWords(info.id, s.job);
  const local = inAlarmForWall(s.alarms) ? mostSevereAlarm(s.alarms.filter((a) => !a.acknowledged)) : null;
  const alarm = local ?? server ?? null;
  const alarmed = alarm !== null;
  // The alarm centre's critical alarm counts as the machine's own (a machine no page watches).
  const shown = shownState(s.activity, s.alarms, !local && server?.severity === 'critical');
  return (
    <article
      className={`wall-card activity-${shown.activity}${alarmed ? ' in-alarm' : ''}${big ? ' big' : ''}${highlighted ? ' highlighted' : ''}`}
      data-testid={big ? 'wall-spotlight-card' : `wall-card-${info.id}`}
      data-activity={shown.activity}
      data-link={s.link}
      data-alarm={alarmed || undefined}
      aria-label={info.name}
    >
      <div className="wall-card-head">
        {inSection ? <h3 className="wall-name">{info.name}</h3> : <h2 className="wall-name">{info.name}</h2>}
        <Badge tone={shown.tone} testId="wall-activity">
          {shown.words}
        </Badge>
      </div>
      {/* The bay whole, on its line (its section's heading names it when grouped by bay). */}
      {info.group && !inSection && (
        <div className="wall-bay" data-testid="wall-bay">
          {info.group}
        </div>
      )}
      <div className="wall-sub">
        {familyLabel(info.kind)}
        {info.simulated && ' · simulated'}
      </div>
      {alarm ? (
        <>
          <div
            className={`wall-alarm tone-${alarm.severity === 'critical' ? 'bad' : 'warn'}`}
            data-testid="wall-alarm"
          >
            {alarm.severity === 'critical' && <span aria-hidden="true">⚠ </span>}
            {alarm.message}
          </div>
          {big && <div className="wall-since">Since {formatTime(alarm.since)}</div>}
        </>
      ) : (
        <div className="wall-label">{s.activityLabel}</div>
      )}
      {s.job && job && (
        <div className="wall-job" data-testid="wall-job">
          <div className="wall-job-name" data-testid="wall-job-name">
            {job.name}
          </div>
          <ProgressBar value={job.fraction} label={`${info.name} job progress`} />
          <div className="wall-job-times">
            <span data-testid="wall-job-percent">{job.percent}</span>
            <span data-testid="wall-job-running">{job.runningFor}</span>
            <span data-testid="wall-job-remaining">{job.remaining}</span>
          </div>
        </div>
      )}
      <div className="wall-foot">
        {s.link !== 'online' && <Badge tone={LINK_TONE[s.link]}>{linkWords(s.link)}</Badge>}
        <MachineAge rt={rt} testId="wall-age" />
      </div>
    </article>
  );
}

function sameIds(a: readonly string[], b: readonly string[]): boolean {
  return a.length === b.length && a.every((id, i) => id === b[i]);
}
