//! A SkiNet Live client in Rust (schemas/ is the contract; messages are msgpack maps).
//!
//! ```text
//! skinet-client [--connect tcp/127.0.0.1:7447] [--system spot_arm]
//!               [--user observer --password PASS] [--check SKILLSET:TRANSITION]...
//!               [--verdicts N] [--timeout SECONDS]
//! ```
//!
//! 1. fetches the model digest from the monitor (`skinet/<system>/model/*`),
//! 2. asks a predictor about the initial marking (`skinet/<system>/predict/<client>`,
//!    a `PredictRequest`) and prints the `PredictReply`,
//! 3. asks the monitor's command check (`skinet/<system>/check/<client>`, a
//!    `CheckRequest`) about each `--check` command and prints the decision and its reasons,
//! 4. prints every `Verdicts` published on `skinet/<system>/verdicts`, until N
//!    were printed (default: forever) or nothing came for the timeout.
//!
//! `<client>` is the `--user` (`local` without a login): the router lets a user ask
//! only under its own name, and the services count requests per name (rate limits).

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use zenoh::{Config, Wait};

const SCHEMA_VERSION: u8 = 1;

#[derive(Debug, Default, Serialize, Deserialize)]
struct SkillsetStatus {
    #[serde(default)]
    resources: BTreeMap<String, String>,
    #[serde(default)]
    running: Vec<String>,
}

#[derive(Debug, Serialize)]
struct PredictRequest {
    v: u8,
    system: String,
    digest: String,
    seq: u64,
    /// The marking to predict from; skillsets left out are at their initial state.
    skillsets: BTreeMap<String, SkillsetStatus>,
    budget: f64,
}

#[derive(Debug, Deserialize)]
struct ModelBundle {
    digest: String,
}

#[derive(Debug, Deserialize)]
struct StateSpaceReport {
    time: f64,
    timeout_reached: bool,
    depth: u64,
    markings: u64,
    edges: u64,
}

#[derive(Debug, Deserialize)]
struct Risk {
    skillsets: BTreeMap<String, SkillsetStatus>,
    property: String,
    status: String,
    /// "fair" or "literal": the AF that decided it (docs/semantics.md §6.2).
    #[serde(default)]
    af: String,
    steps: Option<u64>,
    /// "skillset:transition" per step to the violation.
    #[serde(default)]
    witness: Vec<String>,
}

#[derive(Debug, Deserialize)]
struct PredictReply {
    ok: bool,
    #[serde(default)]
    error: String,
    #[serde(default)]
    instance: String,
    report: Option<StateSpaceReport>,
    #[serde(default)]
    risks: Vec<Risk>,
}

#[derive(Debug, Deserialize)]
struct PropertyVerdict {
    name: String,
    holds: bool,
}

#[derive(Debug, Serialize)]
struct CheckRequest {
    v: u8,
    skillset: String,
    transition: String,
}

#[derive(Debug, Deserialize)]
struct CheckReason {
    property: String,
    constraint: String,
    action: String,
    steps: Option<u64>,
    #[serde(default)]
    witness: Vec<String>,
}

#[derive(Debug, Deserialize)]
struct CheckReply {
    ok: bool,
    decision: Option<String>,
    #[serde(default)]
    reasons: Vec<CheckReason>,
    #[serde(default)]
    error: String,
    #[serde(default)]
    candidates: Vec<String>,
}

#[derive(Debug, Deserialize)]
struct Verdicts {
    seq: u64,
    stamp: f64,
    properties: Vec<PropertyVerdict>,
}

struct Args {
    connect: String,
    system: String,
    user: Option<String>,
    password: String,
    checks: Vec<String>,
    verdicts: Option<u64>,
    timeout: Duration,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        connect: "tcp/127.0.0.1:7447".into(),
        system: "spot_arm".into(),
        user: None,
        password: String::new(),
        checks: Vec::new(),
        verdicts: None,
        timeout: Duration::from_secs(3600),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--connect" | "-e" => args.connect = value()?,
            "--system" => args.system = value()?,
            "--user" => args.user = Some(value()?),
            "--password" => args.password = value()?,
            "--check" => args.checks.push(value()?),
            "--verdicts" => {
                args.verdicts = Some(value()?.parse().map_err(|e| format!("--verdicts: {e}"))?)
            }
            "--timeout" => {
                let secs: f64 = value()?.parse().map_err(|e| format!("--timeout: {e}"))?;
                args.timeout = Duration::from_secs_f64(secs);
            }
            "--help" | "-h" => return Err(String::new()),
            other => return Err(format!("unknown argument '{other}'")),
        }
    }
    Ok(args)
}

fn config(args: &Args) -> zenoh::Result<Config> {
    let mut config = Config::default();
    config.insert_json5("mode", r#""client""#)?;
    config.insert_json5("connect/endpoints", &format!("[{:?}]", args.connect))?;
    config.insert_json5("scouting/multicast/enabled", "false")?;
    if let Some(user) = &args.user {
        config.insert_json5("transport/auth/usrpwd/user", &format!("{user:?}"))?;
        config.insert_json5(
            "transport/auth/usrpwd/password",
            &format!("{:?}", args.password),
        )?;
    }
    Ok(config)
}

fn run(args: Args) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let session = zenoh::open(config(&args)?).wait()?;
    let system = &args.system;
    let client = args.user.as_deref().unwrap_or("local");

    // The model digest identifies the system a predictor must rebuild.
    let mut digest = None;
    for reply in session
        .get(format!("skinet/{system}/model/*"))
        .timeout(Duration::from_secs(5))
        .wait()?
    {
        if let Ok(sample) = reply.result() {
            let bundle: ModelBundle = rmp_serde::from_slice(&sample.payload().to_bytes())?;
            digest = Some(bundle.digest);
            break;
        }
    }
    match digest {
        Some(digest) => {
            println!("model {system} {digest}");
            predict(&session, system, client, digest)?;
        }
        // Observers may not query models or predictors (docker/zenoh/router.json5).
        None => println!("model {system}: no answer on the model key (is a monitor up, may this user ask?)"),
    }

    for command in &args.checks {
        let (skillset, transition) = command
            .split_once(':')
            .ok_or(format!("--check {command}: expected SKILLSET:TRANSITION"))?;
        let request = CheckRequest {
            v: SCHEMA_VERSION,
            skillset: skillset.into(),
            transition: transition.into(),
        };
        let replies = session
            .get(format!("skinet/{system}/check/{client}"))
            .payload(rmp_serde::to_vec_named(&request)?)
            .timeout(Duration::from_secs(5))
            .wait()?;
        let Ok(reply) = replies.recv() else {
            println!("check {command}: no monitor answered");
            continue;
        };
        let Ok(sample) = reply.result() else {
            println!("check {command}: error reply");
            continue;
        };
        let check: CheckReply = rmp_serde::from_slice(&sample.payload().to_bytes())?;
        if !check.ok {
            println!(
                "check {command}: {} (candidates: {})",
                check.error,
                check.candidates.join(", ")
            );
            continue;
        }
        println!("check {command}: {}", check.decision.unwrap_or_default());
        for r in &check.reasons {
            let steps = r.steps.map_or("?".to_string(), |s| s.to_string());
            println!(
                "  {} {} ({}) in {} steps via [{}]",
                r.property,
                r.constraint,
                r.action,
                steps,
                r.witness.join(", ")
            );
        }
    }

    let subscriber = session
        .declare_subscriber(format!("skinet/{system}/verdicts"))
        .wait()?;
    println!("following skinet/{system}/verdicts");
    let mut count = 0;
    while args.verdicts.is_none_or(|n| count < n) {
        let Some(sample) = subscriber.recv_timeout(args.timeout)? else {
            println!("no verdicts for {:?}", args.timeout);
            break;
        };
        match rmp_serde::from_slice::<Verdicts>(&sample.payload().to_bytes()) {
            Ok(v) => {
                let props: Vec<String> = v
                    .properties
                    .iter()
                    .map(|p| format!("{}={}", p.name, if p.holds { "holds" } else { "VIOLATED" }))
                    .collect();
                println!("verdicts #{} at {:.3}: {}", v.seq, v.stamp, props.join(" "));
                count += 1;
            }
            Err(e) => println!("undecodable verdicts: {e}"),
        }
    }
    session.close().wait()?;
    Ok(())
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(args) => args,
        Err(msg) => {
            let usage = "usage: skinet-client [--connect ENDPOINT] [--system NAME] [--user U --password P] \
                         [--check SKILLSET:TRANSITION]... [--verdicts N] [--timeout SECONDS]";
            if msg.is_empty() {
                println!("{usage}");
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {msg}\n{usage}");
            return ExitCode::from(2);
        }
    };
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Asks the predictors about the initial marking of `system` and prints the reply.
fn predict(
    session: &zenoh::Session,
    system: &str,
    client: &str,
    digest: String,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let request = PredictRequest {
        v: SCHEMA_VERSION,
        system: system.to_string(),
        digest,
        seq: 1,
        skillsets: BTreeMap::new(),
        budget: 1.0,
    };
    let replies = session
        .get(format!("skinet/{system}/predict/{client}"))
        .payload(rmp_serde::to_vec_named(&request)?)
        .timeout(Duration::from_secs(10))
        .wait()?;
    let mut answered = false;
    while let Ok(reply) = replies.recv() {
        match reply.result() {
            Ok(sample) => {
                let reply: PredictReply = rmp_serde::from_slice(&sample.payload().to_bytes())?;
                answered = true;
                if !reply.ok {
                    println!("prediction failed ({}): {}", reply.instance, reply.error);
                    continue;
                }
                if let Some(r) = &reply.report {
                    println!(
                        "prediction by {}: {} markings, {} edges, depth {}, {:.3} s{}",
                        reply.instance,
                        r.markings,
                        r.edges,
                        r.depth,
                        r.time,
                        if r.timeout_reached {
                            " (truncated)"
                        } else {
                            ""
                        }
                    );
                }
                for risk in &reply.risks {
                    let marking: Vec<String> = risk
                        .skillsets
                        .iter()
                        .map(|(name, s)| {
                            format!("{name}: {:?} running {:?}", s.resources, s.running)
                        })
                        .collect();
                    let steps = risk.steps.map_or("?".to_string(), |s| s.to_string());
                    println!(
                        "  risk {} {} ({} AF) in {} steps from {}; witness: {}",
                        risk.property,
                        risk.status,
                        risk.af,
                        steps,
                        marking.join("; "),
                        risk.witness.join(" -> ")
                    );
                }
            }
            Err(err) => println!(
                "prediction error: {}",
                String::from_utf8_lossy(&err.payload().to_bytes())
            ),
        }
    }
    if !answered {
        println!("no predictor answered");
    }

    Ok(())
}
